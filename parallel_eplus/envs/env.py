"""`EnergyPlusEnv`: the data center as a Gymnasium environment (one EnergyPlus process per episode)."""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np

from parallel_eplus.buildings.building import load_building
from parallel_eplus.buildings.model import SCHEDULE_FEATURES, TIME_FEATURES
from parallel_eplus.buildings.reward import RewardConfig
from parallel_eplus.buildings.spec import reward_config
from parallel_eplus.engine.config import SimulationConfig
from parallel_eplus.engine.simulation import Simulation


def observation_space(
    time_features: bool = False, schedule_features: bool = False, building: str | Path | None = None
) -> gym.spaces.Box:
    """The building's sensors (None: the data center) and the opt-in features, which lie in [-1, 1]."""
    low, high = load_building(building).bounds()
    extra = len(TIME_FEATURES) * time_features + len(SCHEDULE_FEATURES) * schedule_features
    low, high = low + [-1.0] * extra, high + [1.0] * extra
    return gym.spaces.Box(np.array(low, np.float32), np.array(high, np.float32), dtype=np.float32)


def action_space(n: int) -> gym.spaces.Box:
    return gym.spaces.Box(-1.0, 1.0, shape=(n,), dtype=np.float32)


class EnergyPlusEnv(gym.Env):
    """The paper's environment: 6 observations, 2 or 4 normalized actions, its reward.

    `time_features=True` appends hour and day of week as sine/cosine pairs (`model.TIME_FEATURES`);
    `schedule_features=True` then the IT-load schedule's present value and its steps (`model.SCHEDULE_FEATURES`).
    `residual_scale > 0`: the action corrects the rule-based controller's by up to that much (rbc.py):
    each normalized action (`residual_space="action"`) or, with `"demand"`, each zone's flow demand
    (two elements, up to `residual_scale` kg/s).

    `building`: a spec file (buildings/spec.py) whose IDF, sensors, actions and reward replace the data
    center's (`model` then does not apply); its reward parameters are the default `reward`.

    `reset()` starts a new EnergyPlus process (stopping a running one) and returns the state at the
    start of the run period; each `step()` runs one 15-minute zone timestep under the given action.
    The episode ends (`terminated=True`) after the run period's last timestep.
    """

    metadata = {"render_modes": []}

    def __init__(
        self,
        weather: str | Path | list[str] = "CA",
        model: str = "temp_fan",
        run_days: int = 365,
        output_dir: str | Path | None = None,
        keep_episodes: int | None = None,
        reward: RewardConfig | Mapping[str, float] | str | None = None,
        step_timeout_s: float = 60.0,
        start_timeout_s: float = 180.0,
        idf: str | Path | None = None,
        time_features: bool = False,
        schedule_features: bool = False,
        residual_scale: float = 0.0,
        residual_space: str = "action",
        rbc_target_c: float | None = None,
        building: str | Path | None = None,
    ):
        weathers = [str(w) for w in weather] if isinstance(weather, (list, tuple)) else [str(weather)]
        if building is not None:  # a typo costs seconds and a message naming it, not a hung worker
            from parallel_eplus.buildings.check import check_building

            check_building(building)
        self.config = SimulationConfig(
            weather=weathers[0],
            model=model,
            run_days=run_days,
            output_dir=None if output_dir is None else str(output_dir),
            keep_episodes=keep_episodes,
            reward=reward_config(load_building(building).spec) if reward is None else RewardConfig.from_any(reward),
            start_timeout_s=start_timeout_s,
            step_timeout_s=step_timeout_s,
            idf=None if idf is None else str(idf),
            time_features=time_features,
            schedule_features=schedule_features,
            residual_scale=residual_scale,
            residual_space=residual_space,
            rbc_target_c=rbc_target_c,
            building=None if building is None else str(building),
        )
        self.sim = Simulation(self.config, weathers)
        if not self.sim.elements:
            raise ValueError(f"model {model!r} has no agent actions; it runs through the evaluation sweep")
        self.observation_space = observation_space(time_features, schedule_features, building)
        self.action_space = action_space(len(self.sim.policy_names))

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        super().reset(seed=seed)
        weather_index = (options or {}).get("weather_index")
        return self.sim.start(weather_index)

    def step(self, action):
        self.sim.send(action)
        obs, reward, terminated, info = self.sim.receive()
        return obs, reward, terminated, False, info

    @property
    def episode_dir(self) -> Path | None:
        return self.sim.episode_dir

    def close(self) -> None:
        self.sim.close()
