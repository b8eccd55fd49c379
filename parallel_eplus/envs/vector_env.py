"""Many EnergyPlus processes as one Gymnasium vector env, with no process in between.

A vector step writes every worker's action, then reads every observation: one pipe round trip per
worker, all EnergyPlus processes computing at once. Finished episodes restart in the same step
(Gymnasium's SAME_STEP autoreset: the final observation and info are in `final_obs` / `final_info`).
A worker whose EnergyPlus crashes restarts its episode (the cut episode ends as truncated) up to
`max_restarts` times in a row, then the run fails with the worker's error.

Workers can also be stepped one by one (`send_one`, `ready`, `receive_one`), so a learner can hand each
worker its next action as soon as its own observation arrives instead of waiting for the slowest
(pipelining; `rollout.py`).
"""

from __future__ import annotations

import logging
from dataclasses import replace
from pathlib import Path

import gymnasium as gym
import numpy as np
from gymnasium.vector import AutoresetMode
from gymnasium.vector.utils import batch_space

from parallel_eplus.buildings.building import Building
from parallel_eplus.engine.config import SimulationConfig
from parallel_eplus.engine.episode import record_failure
from parallel_eplus.engine.simulation import Simulation, wait_any
from parallel_eplus.envs.env import action_space, observation_space
from parallel_eplus.errors import EnergyPlusError

log = logging.getLogger(__name__)


def weather_shares(weathers: list[str], num_workers: int, done: list[int] | None = None) -> list[list[str]]:
    """Every worker cycles through all the weathers, worker i starting i places along, so each weather
    gets an equal share of episodes whatever the worker count (the paper alternates them evenly).

    `done[i]`: episodes worker i already finished (a resumed run), so its cycle continues where it was.
    """
    k = len(weathers)
    starts = [(i + (done[i] if done else 0)) % k for i in range(num_workers)]
    return [weathers[s:] + weathers[:s] for s in starts]


class EnergyPlusVectorEnv(gym.vector.VectorEnv):
    """N `Simulation`s stepped together; each keeps its own pipes, process and episode directory."""

    metadata = {"autoreset_mode": AutoresetMode.SAME_STEP}

    def __init__(
        self,
        config: SimulationConfig,
        shares: list[list[str]],
        max_restarts: int = 3,
        first_worker: int = 0,
        building: Building | None = None,
    ):
        """One worker per entry of `shares`: the weathers it cycles through (see `weather_shares`). `building`: the
        config's, as the command resolved it (None: resolved from the config)."""
        self.num_envs = num_envs = len(shares)
        self.max_restarts = max_restarts
        self.sims: list[Simulation] = []
        try:
            for i, share in enumerate(shares):
                worker = first_worker + i
                out = None if config.output_dir is None else str(Path(config.output_dir) / f"worker-{worker}")
                sim = Simulation(
                    replace(config, output_dir=out), share, name=str(worker), siblings=len(shares),
                    prepare=config.prepare_next, building=building,
                )  # fmt: skip
                self.sims.append(sim)
        except BaseException:
            self.close()
            raise
        n_actions = len(self.sims[0].policy_names)
        self.single_observation_space = observation_space(
            config.time_features, config.schedule_features, self.sims[0].building, config.forecast_hours
        )
        self.single_action_space = action_space(n_actions)
        self.observation_space = batch_space(self.single_observation_space, num_envs)
        self.action_space = batch_space(self.single_action_space, num_envs)
        self._failures = [0] * num_envs
        self._send_errors: dict[int, EnergyPlusError] = {}
        self._starting: dict[int, tuple] = {}  # worker -> its last step's answer, held until its next episode starts
        self._obs = np.zeros((num_envs, *self.single_observation_space.shape), dtype=np.float32)

    # -- Gymnasium API ------------------------------------------------------------------------
    def reset(self, *, seed: int | None = None, options: dict | None = None):
        if seed is not None:
            self.action_space.seed(seed)
        infos = self.start_all(range(self.num_envs))
        return self._obs.copy(), self._as_dict(infos)

    def step(self, actions):
        obs, rewards, terminated, truncated, infos = self.step_lists(actions)
        return obs, rewards, terminated, truncated, self._as_dict(infos)

    def observations(self) -> np.ndarray:
        """Every worker's current observation, stacked."""
        return self._obs.copy()

    # -- list-of-dicts variants, used by the SB3 adapter and the Ray actors ------------------------
    def start_all(self, indices) -> list[dict]:
        """(Re)start the given workers' episodes at once; returns their first infos."""
        indices = list(indices)
        infos: list[dict] = [{} for _ in range(self.num_envs)]
        for i in indices:
            self._send_errors.pop(i, None)  # from an action to an episode now gone
            self._starting.pop(i, None)
            self.sims[i].launch()
        for i in indices:
            self._obs[i], infos[i] = self._first_observation(i)
        return infos

    def step_lists(self, actions) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, list[dict]]:
        """One lockstep vector step: (observations, rewards, terminated, infos) as lists, no auto-reset copies."""
        actions = np.asarray(actions)
        n = self.num_envs
        for i in range(n):
            self.send_one(i, actions[i])
        rewards = np.zeros(n)
        terminated = np.zeros(n, dtype=bool)
        truncated = np.zeros(n, dtype=bool)
        infos: list[dict] = [{} for _ in range(n)]
        ended = []
        for i in range(n):
            rewards[i], terminated[i], infos[i], error = self._collect(i)
            if terminated[i] or error is not None:
                truncated[i] = error is not None
                infos[i] = self._end_episode(i, infos[i], error)
                ended.append(i)
        for i in ended:  # after every launch, so the new episodes start up at once
            self._obs[i], first = self._first_observation(i)
            infos[i].update(first)
        return self._obs.copy(), rewards, terminated, truncated, infos

    # -- one worker at a time, for pipelining ---------------------------------------------------
    def send_one(self, i: int, action) -> None:
        """Send worker i its action; a failure is kept and reported by `receive_one`."""
        try:
            self.sims[i].send(action)
        except EnergyPlusError as e:
            self._send_errors[i] = e

    def ready(self, indices) -> list[int]:
        """The workers among `indices` whose answer is in: an observation (a first one, for a worker
        starting an episode), a failure, or a deadline passed.

        Blocks until there is at least one. Like a single worker's read, it polls for the workers' spin
        time first (none when the workers and the learner have no spare core: see `spin.default_spin_s`).
        """
        return wait_any([sim.process for sim in self.sims], indices, self._send_errors)

    def receive_one(self, i: int) -> tuple[np.ndarray, float, bool, bool, dict] | None:
        """Worker i's (observation, reward, terminated, truncated, info) for its last action, as `step`
        gives them for each worker; None while its next episode starts up after one finished or failed.

        The start-up (~0.5 s) runs while the other workers are served: ask again once `ready` reports it.
        """
        if i in self._starting:
            try:
                self._obs[i], first = self.sims[i].first_observation()
            except EnergyPlusError as e:
                self._restart(i, e)
                return None
            reward, terminated, truncated, info = self._starting.pop(i)
            info.update(first)
            return self._obs[i].copy(), reward, terminated, truncated, info
        reward, terminated, info, error = self._collect(i)
        if terminated or error is not None:
            self._starting[i] = (reward, terminated, error is not None, self._end_episode(i, info, error))
            return None
        return self._obs[i].copy(), reward, False, False, info

    # -- internals ----------------------------------------------------------------------------
    def _first_observation(self, i: int) -> tuple[np.ndarray, dict]:
        while True:
            try:
                return self.sims[i].first_observation()
            except EnergyPlusError as e:
                self._restart(i, e)

    def _collect(self, i: int) -> tuple[float, bool, dict, EnergyPlusError | None]:
        """Worker i's answer to its last action, into `_obs[i]`: (reward, terminated, info, its failure)."""
        error = self._send_errors.pop(i, None)
        if error is None:
            try:
                self._obs[i], reward, terminated, info = self.sims[i].receive()
                return reward, terminated, info, None
            except EnergyPlusError as e:
                error = e
        return 0.0, False, {}, error

    def _end_episode(self, i: int, info: dict, error: EnergyPlusError | None) -> dict:
        """Launch worker i's next episode after one finished (or failed); returns the autoreset info."""
        if error is None:
            self._failures[i] = 0
            self.sims[i].launch()
            return {"final_obs": self._obs[i].copy(), "final_info": info}
        final = {"final_obs": self._obs[i].copy(), "final_info": {}, "energyplus_error": str(error)}
        self._restart(i, error)
        return final

    def _restart(self, i: int, error: EnergyPlusError) -> None:
        """Relaunch worker i's episode on the same weather, or fail the run after too many tries."""
        self._failures[i] += 1
        sim = self.sims[i]
        record_failure(error.episode_dir, error)
        if self._failures[i] > self.max_restarts:
            raise EnergyPlusError(
                f"worker {sim.name} failed {self._failures[i]} times in a row on weather {sim.weather}; "
                f"giving up. Last error: {error}",
                error.episode_dir,
            ) from error
        log.warning(
            "worker %s: EnergyPlus failed (%s); restarting its episode (%d/%d)",
            sim.name, error.headline, self._failures[i], self.max_restarts,
        )  # fmt: skip
        sim.launch(sim.weather_index)

    def _as_dict(self, infos: list[dict]) -> dict:
        out: dict = {}
        for i, info in enumerate(infos):
            out = self._add_info(out, info, i)
        return out

    def close_extras(self, **kwargs) -> None:
        for sim in self.sims:
            sim.close()
