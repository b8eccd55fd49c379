"""Ray backend: each actor hosts a group of EnergyPlus workers (a local `EnergyPlusVectorEnv`) on its node.

The learner steps every actor at once and concatenates the results, so anywhere in the cluster the
same learner code sees one vector env.
"""

from __future__ import annotations

import logging

import numpy as np

from .env import action_space, observation_space
from .simulation import SimulationConfig, policy_action_names

log = logging.getLogger(__name__)


def _actor_class():
    import ray

    from .vector_env import EnergyPlusVectorEnv

    @ray.remote
    class WorkerGroup:
        def __init__(self, config: SimulationConfig, shares: list[list[str]], first_worker: int, max_restarts: int):
            logging.basicConfig(level=logging.INFO)
            self.venv = EnergyPlusVectorEnv(config, shares, max_restarts=max_restarts, first_worker=first_worker)

        def start_all(self, indices):
            infos = self.venv.start_all(indices)
            return self.venv.observations(), infos

        def step(self, actions):
            return self.venv.step_lists(actions)

        def close(self):
            self.venv.close()

    return WorkerGroup


class RayVectorEnv:
    """Groups of workers in Ray actors, stepped together: write all actions, then gather all results."""

    def __init__(
        self,
        config: SimulationConfig,
        shares: list[list[str]],
        workers_per_actor: int,
        address: str | None = None,
        max_restarts: int = 3,
    ):
        import ray

        self._owns_ray = not ray.is_initialized()
        if self._owns_ray:
            if address:
                ray.init(address=address, log_to_driver=True)
            else:
                ray.init(num_cpus=len(shares), include_dashboard=False, log_to_driver=True)
        self.num_envs = len(shares)
        self.single_observation_space = observation_space(config.time_features, config.schedule_features)
        self.single_action_space = action_space(len(policy_action_names(config)))
        group = _actor_class()
        self.slices: list[slice] = []
        self.actors = []
        for start in range(0, self.num_envs, workers_per_actor):
            part = shares[start : start + workers_per_actor]
            self.slices.append(slice(start, start + len(part)))
            actor = group.options(num_cpus=len(part)).remote(config, part, start, max_restarts)
            self.actors.append(actor)
        self._obs = np.zeros((self.num_envs, *self.single_observation_space.shape), dtype=np.float32)
        log.info("Ray backend: %d workers in %d actors", self.num_envs, len(self.actors))

    def observations(self) -> np.ndarray:
        return self._obs.copy()

    def start_all(self, indices) -> list[dict]:
        import ray

        wanted = set(indices)
        calls = []
        for actor, sl in zip(self.actors, self.slices, strict=True):
            local = [i - sl.start for i in range(sl.start, sl.stop) if i in wanted]
            calls.append((sl, actor.start_all.remote(local)))
        infos: list[dict] = []
        for sl, ref in calls:
            obs, part = ray.get(ref)
            self._obs[sl] = obs
            infos.extend(part)
        return infos

    def step_lists(self, actions):
        import ray

        refs = [actor.step.remote(actions[sl]) for actor, sl in zip(self.actors, self.slices, strict=True)]
        results = ray.get(refs)
        obs = np.concatenate([r[0] for r in results])
        self._obs[:] = obs
        rewards = np.concatenate([r[1] for r in results])
        terminated = np.concatenate([r[2] for r in results])
        truncated = np.concatenate([r[3] for r in results])
        infos = [info for r in results for info in r[4]]
        return obs, rewards, terminated, truncated, infos

    def close(self) -> None:
        import ray

        if not self.actors:
            return
        try:
            ray.get([a.close.remote() for a in self.actors], timeout=60)
        except Exception as e:  # noqa: BLE001 - closing must not mask the original error
            log.warning("closing Ray workers: %s", e)
        for a in self.actors:
            ray.kill(a)
        self.actors = []
        if self._owns_ray:
            ray.shutdown()
