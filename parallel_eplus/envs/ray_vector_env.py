"""Ray backend: each actor hosts a group of EnergyPlus workers (a local `EnergyPlusVectorEnv`) on its node.

The learner sees one vector env either way: `step_lists` steps every actor at once and concatenates
the results; pipelined (`send_one` / `ready` / `receive_one`, as the local vector env offers them) each
actor steps as soon as all its workers have their actions, so no actor waits for the slowest of the
cluster, only for the slowest of its own group.
"""

from __future__ import annotations

import logging

import numpy as np

from parallel_eplus.engine.config import SimulationConfig, policy_action_names
from parallel_eplus.envs.env import action_space, observation_space

log = logging.getLogger(__name__)


def _actor_class():
    import ray

    from parallel_eplus.envs.vector_env import EnergyPlusVectorEnv

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

        def node(self) -> str:
            import socket

            return f"{socket.gethostname()} ({ray.util.get_node_ip_address()})"

    return WorkerGroup


def _log_placement(actors, slices, timeout_s: float = 60.0) -> None:
    """The cluster's resources and how many workers each node got: what a user checks first on a cluster."""
    import collections

    import ray

    res = ray.cluster_resources()
    nodes = [n for n in ray.nodes() if n.get("Alive")]
    log.info("Ray cluster: %d node(s), %.0f CPUs, %.1f GiB memory", len(nodes), res.get("CPU", 0),
             res.get("memory", 0) / 2**30)  # fmt: skip
    placed = ray.get([a.node.remote() for a in actors], timeout=timeout_s)
    per_node: collections.Counter = collections.Counter()
    for node, sl in zip(placed, slices, strict=True):
        per_node[node] += sl.stop - sl.start
    for node, n in per_node.items():
        log.info("  %s: %d worker(s)", node, n)


class RayVectorEnv:
    """Groups of workers in Ray actors: stepped together (`step_lists`) or each group as soon as it answers."""

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
                # "local": a new Ray of our own, whatever an earlier cluster left in Ray's temp folder
                # (a stale ray_current_cluster file) or in RAY_ADDRESS (only read when no address is given).
                ray.init(address="local", num_cpus=len(shares), include_dashboard=False, log_to_driver=True)
        self.num_envs = len(shares)
        self.single_observation_space = observation_space(
            config.time_features, config.schedule_features, config.building
        )
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
        self._actor_of = [j for j, sl in enumerate(self.slices) for _ in range(sl.start, sl.stop)]
        self._actions = np.zeros((self.num_envs, *self.single_action_space.shape), dtype=np.float32)
        self._staged = [0] * len(self.actors)  # actions received for each actor's next step
        self._in_flight: dict = {}  # ObjectRef of an actor's step -> actor index
        self._answers: dict[int, tuple] = {}  # worker -> its answer, fetched but not yet received
        log.info("Ray backend: %d workers in %d actors", self.num_envs, len(self.actors))
        _log_placement(self.actors, self.slices)

    def observations(self) -> np.ndarray:
        return self._obs.copy()

    def start_all(self, indices) -> list[dict]:
        import ray

        wanted = set(indices)
        # A rollout stopped midway leaves steps in flight: each actor finishes its step before it
        # restarts (its calls run in order), and those answers belong to the episodes being replaced.
        if wanted >= set(range(self.num_envs)):
            self._in_flight.clear()
            self._answers.clear()
            self._staged = [0] * len(self.actors)
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

    # -- one worker at a time, for pipelining ---------------------------------------------------
    def send_one(self, i: int, action) -> None:
        """Stage worker i's action; its actor steps once every worker of its group has one."""
        j = self._actor_of[i]
        self._actions[i] = action
        self._staged[j] += 1
        sl = self.slices[j]
        if self._staged[j] == sl.stop - sl.start:
            self._staged[j] = 0
            self._in_flight[self.actors[j].step.remote(self._actions[sl].copy())] = j

    def ready(self, indices) -> list[int]:
        """The workers among `indices` whose answer is in, waiting for the first actor to finish if none is."""
        import ray

        wanted = list(indices)
        if not any(i in self._answers for i in wanted):
            if not self._in_flight:
                raise RuntimeError("no Ray actor is stepping: send every worker of a group its action first")
            done, _ = ray.wait(list(self._in_flight), num_returns=1)
            for ref in done:
                j = self._in_flight.pop(ref)
                obs, rewards, terminated, truncated, infos = ray.get(ref)  # an actor's error surfaces here
                for k, i in enumerate(range(self.slices[j].start, self.slices[j].stop)):
                    self._answers[i] = (obs[k], float(rewards[k]), bool(terminated[k]), bool(truncated[k]), infos[k])
        return [i for i in wanted if i in self._answers]

    def receive_one(self, i: int) -> tuple[np.ndarray, float, bool, bool, dict]:
        """Worker i's (observation, reward, terminated, truncated, info); an actor resets its own workers."""
        answer = self._answers.pop(i)
        self._obs[i] = answer[0]
        return answer

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
