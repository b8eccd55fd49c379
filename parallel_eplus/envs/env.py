"""`EnergyPlusEnv`: the data center as a Gymnasium environment (one EnergyPlus process per episode)."""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np

from parallel_eplus.buildings.building import Building, load_building
from parallel_eplus.buildings.datacenter import SCHEDULE_FEATURES, TIME_FEATURES
from parallel_eplus.buildings.scoring.reward import RewardConfig, reward_config
from parallel_eplus.engine.config import SimulationConfig
from parallel_eplus.engine.simulation import Simulation


def observation_space(
    time_features: bool = False,
    schedule_features: bool = False,
    building: str | Path | Building | None = None,
    forecast_hours: int = 0,
) -> gym.spaces.Box:
    """The building's sensors (a spec, or its `Building` resolved; None: the data center), the opt-in features,
    which lie in [-1, 1], then its forecasts and `forecast_hours` of the outdoor dry bulb (weather/forecast_features.py;
    the EPW's bounds)."""
    from parallel_eplus.buildings.weather.forecast_features import outdoor_forecast

    b = load_building(building)
    spec = b.spec
    low, high = b.bounds()
    extra = len(TIME_FEATURES) * time_features + len(SCHEDULE_FEATURES) * schedule_features
    low, high = low + [-1.0] * extra, high + [1.0] * extra
    for f in spec.forecasts + ((outdoor_forecast(forecast_hours),) if forecast_hours else ()):
        low, high = low + [f.low] * f.count, high + [f.high] * f.count
    return gym.spaces.Box(np.array(low, np.float32), np.array(high, np.float32), dtype=np.float32)


def action_space(n: int) -> gym.spaces.Box:
    """n normalized action elements, each in [-1, 1]."""
    return gym.spaces.Box(-1.0, 1.0, shape=(n,), dtype=np.float32)


class EnergyPlusEnv(gym.Env):
    """The paper's data center under learned cooling control: one EnergyPlus process per episode.

    ## Description
    EnergyPlus's two-zone data center (`2ZoneDataCenterHVAC_wEconomizer`, West and East zones, each with
    its own air loop) with the built-in setpoint managers and fan control replaced by the agent
    (Moriyama et al. 2018). `reset()` starts the next episode on the next weather file (prepared while the
    last one ran, so it is already at its first step: engine/episodes/prepared.py), over a private pair of named pipes;
    every `step()` runs one zone timestep (15 minutes) under the action.

    ## Action Space
    `Box(-1, 1, (4,))`, scaled linearly to physical units (`buildings/datacenter.py` `ACTIONS`): West and
    East supply-air setpoints (10–40 °C, written to four setpoint nodes per zone), West and East supply
    fan mass flow (1.75–7.0 kg/s). `model="temp"`: the two setpoints only. With `residual_scale > 0`
    the action corrects the rule-based controller's (`residual_space="action"`: each element;
    `"demand"`: two elements, each zone's flow demand, up to `residual_scale` kg/s); with a spec building,
    `residual_space="builtin"` corrects its own thermostat schedules by up to `residual_scale` of each
    action's half-range (engine/config.py). A non-finite
    action raises `ValueError` naming the element.

    ## Observation Space
    `Box(float32)` of the paper's six (`model.SENSORS`): outdoor, West and East zone temperatures (°C;
    −20 to 50) and total, IT and HVAC electric power (W). `time_features=True` appends hour and day of
    week as sine/cosine pairs; `schedule_features=True` the IT-load schedule's value and steps
    (`model.TIME_FEATURES`, `model.SCHEDULE_FEATURES`; each in [−1, 1]). `info` carries every raw
    value by name, the simulated `time` and the `weather`.

    ## Rewards
    The paper's: a Gaussian plus a trapezoid around 23.5 °C (band 23–24 °C) per zone, minus
    λ_P × total power (`buildings/scoring/reward.py`, constants in `RewardConfig`; `reward=` overrides them).

    ## Starting State
    The weather file's January 1, 00:00, after EnergyPlus's sizing and warmup under each action's
    `initial` value.

    ## Episode End
    `terminated=True` after the run period's last timestep (`run_days`, a year by default); `info`
    then holds `episode_summary` (power, temperatures, % in band) and `episode_dir`. Never truncated.
    A crashed or silent EnergyPlus raises `EnergyPlusError` within `step_timeout_s`.

    ## Arguments
    `weather`: a short name (CA, CO, FL, IL, VA), an EPW path, or a list cycled episode by episode;
    `run_days`; `output_dir` and `keep_episodes` for episode records (envs sharing one `output_dir`, in one process
    or several, each get their own `episode-NNNNNN-<weather>` directories); `energyplus_csv=False` drops
    EnergyPlus's own `eplusout.csv` from them (training does: it costs memory and time); `prepare_next=False`
    starts every episode cold instead of preparing the next while one runs (episodes/prepared.py); `fork_episodes=False`
    prepares each in a long-lived process instead of forking it from one parked at its first step (episodes/fork.py);
    `reward`; `idf` to override the model file; `start_timeout_s`, `step_timeout_s`; `time_features`,
    `schedule_features` (None: the spec's); `residual_scale`, `residual_space`, `rbc_target_c`; `building`: a spec
    file or a built-in spec's name
    (buildings/spec/load.py) whose model, sensors, actions and reward replace the data center's (`model` then does
    not apply; its reward parameters are the default `reward`; it is checked against its model first);
    `name`: the `worker` its episodes' summaries name (`rllib_env` names RLlib's env runners).
    `weather_noise` ("drybulb=1:0:24", buildings/weather/noise.py): each episode runs a perturbed copy of its
    weather file, seeded by `reset(seed=)` (same seed, same year) or else by `seed`, the worker and the episode;
    `forecast_hours`: the outdoor dry bulb's next N hours end the observation, with BOPTEST's `forecast_error`
    ("low", "medium", "high"; None: exact) (docs/weather.md).
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
        time_features: bool | None = None,
        schedule_features: bool | None = None,
        residual_scale: float = 0.0,
        residual_space: str = "action",
        rbc_target_c: float | None = None,
        building: str | Path | None = None,
        energyplus_csv: bool = True,
        name: str = "0",
        prepare_next: bool = True,
        fork_episodes: bool = True,
        weather_noise: str | None = None,
        forecast_hours: int = 0,
        forecast_error: str | None = None,
        seed: int = 0,
    ):
        weathers = [str(w) for w in weather] if isinstance(weather, (list, tuple)) else [str(weather)]
        if building is not None:  # a typo costs seconds and a message naming it, not a hung worker
            from parallel_eplus.buildings.check.names import check_building

            check_building(building)
        spec = load_building(building).spec  # its opt-in features unless given here (the data center's: off)
        time_features = spec.time_features if time_features is None else time_features
        schedule_features = spec.schedule_features if schedule_features is None else schedule_features
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
            energyplus_csv=energyplus_csv,
            prepare_next=prepare_next,
            fork_episodes=fork_episodes,
            weather_noise=weather_noise,
            forecast_hours=forecast_hours,
            forecast_error=forecast_error,
            seed=seed,
        )
        # `name`: the `worker` its episodes' summaries name
        self.sim = Simulation(self.config, weathers, name=name, prepare=prepare_next)
        if not self.sim.elements:
            raise ValueError(f"model {model!r} has no agent actions; it runs through the evaluation sweep")
        self.observation_space = observation_space(time_features, schedule_features, building, forecast_hours)
        self.action_space = action_space(len(self.sim.policy_names))

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        super().reset(seed=seed)
        options = dict(options or {})
        weather_index = options.pop("weather_index", None)
        # The episode this reset asks for: the one prepared while the last ran if it was planned for the same
        # weather, seed and options (the rotation's next, no seed, no options), else a cold start (prepared.py).
        return self.sim.start(plan=self.sim.next_plan(weather_index, seed, options))

    def step(self, action):
        self.sim.send(action)
        obs, reward, terminated, info = self.sim.receive()
        return obs, reward, terminated, False, info

    @property
    def episode_dir(self) -> Path | None:
        """Where the running (or last) episode writes its files."""
        return self.sim.episode_dir

    def close(self) -> None:
        self.sim.close()


def rllib_env(context) -> EnergyPlusEnv:
    """RLlib's env creator (`config.environment(rllib_env, env_config={...})`): the env of one env runner, its
    episodes' `worker` named `runner-<worker_index>` (and `-env-<vector_index>` for a runner's further envs), so
    the summaries of runners sharing one output folder say whose they are. `context` is RLlib's EnvContext: the
    env_config dict with `worker_index` and `vector_index` (0 for the local runner)."""
    worker, vector = int(getattr(context, "worker_index", 0)), int(getattr(context, "vector_index", 0))
    kwargs = {k: v for k, v in dict(context).items() if k != "num_envs"}
    return EnergyPlusEnv(**kwargs, name=f"runner-{worker}" + (f"-env-{vector}" if vector else ""))
