"""Ray backend, the learner's side: groups of EnergyPlus workers in Ray actors, one group per actor.

Training collects a batch with one call per actor (`send`: the policy out; `receive`: a trajectory
fragment back; learning/ray_actor.py, learning/fragments.py), so no Ray call is made per control step.
With `train --overlap` the next batch is sent before the learner updates on the last one. The vector
env API (`start_all`, `step_lists`) remains for what steps the workers one step at a time: SAC's
off-policy loop and a `lockstep` run.

Every wait has a deadline. A collection that stops making progress for `stall_s` (no observation
served in any worker of an actor), an actor that does not answer a progress check within
`answer_s`, or an actor that dies with its node, raises `WorkerLostError` naming the node.
"""

from __future__ import annotations

import collections
import logging
import time
from dataclasses import dataclass, field

import numpy as np

from parallel_eplus.engine.config import SimulationConfig, policy_action_names
from parallel_eplus.engine.pipes import leftovers
from parallel_eplus.envs.env import action_space, observation_space
from parallel_eplus.envs.ray_session import connect
from parallel_eplus.errors import EnergyPlusError, WorkerLostError
from parallel_eplus.learning.ray_actor import actor_class

log = logging.getLogger(__name__)


@dataclass
class BatchStats:
    """What one batch cost the learner in Ray: counted calls and seconds spent waiting."""

    round_trips: int = 0  # collect calls: one per actor
    progress_checks: int = 0  # deadline checks made while waiting (none when a batch is quick)
    wait_s: float = 0.0  # learner idle: from asking for the fragments to the last one in
    collect_s: list[float] = field(default_factory=list)  # per actor, measured on its node
    merge_s: float = 0.0  # learner: fragments into the buffer and the statistics, callbacks


class RayVectorEnv:
    """Groups of workers in Ray actors: a batch per call (`collect`), or a step per call (`step_lists`)."""

    def __init__(
        self,
        config: SimulationConfig,
        shares: list[list[str]],
        workers_per_actor: int,
        address: str | None = None,
        max_restarts: int = 3,
        answer_s: float = 30.0,
    ):
        import ray

        self._owns_ray = connect(address, len(shares))
        self.num_envs = len(shares)
        self.single_observation_space = observation_space(
            config.time_features, config.schedule_features, config.building, config.forecast_hours
        )
        self.single_action_space = action_space(len(policy_action_names(config)))
        # A worker silent for step_timeout_s is restarted inside its actor; an actor that serves no
        # observation for twice that (plus an episode's start-up) is lost.
        self.stall_s = 2 * config.step_timeout_s + 60.0
        self.answer_s = answer_s
        self.poll_s = min(30.0, self.stall_s / 4)
        group = actor_class()
        self.slices: list[slice] = []
        self.actors: list = []
        self.nodes: list[str] = []
        self.stats: list[BatchStats] = []
        self._batch = 0  # batches ordered so far
        self._in_flight: list | None = None  # the batch on order: one reference per actor
        self._received = BatchStats()  # the last batch received
        for start in range(0, self.num_envs, workers_per_actor):
            part = shares[start : start + workers_per_actor]
            self.slices.append(slice(start, start + len(part)))
            self.actors.append(group.options(num_cpus=len(part)).remote(config, part, start, max_restarts))
        self._obs = np.zeros((self.num_envs, *self.single_observation_space.shape), dtype=np.float32)
        try:
            self.nodes = ray.get([a.node.remote() for a in self.actors], timeout=120)
        except Exception:
            self.close()
            raise
        _log_placement(self.nodes, self.slices)

    def observations(self) -> np.ndarray:
        return self._obs.copy()

    def start_all(self, indices) -> list[dict]:
        wanted = set(indices)
        calls = []
        for actor, sl in zip(self.actors, self.slices, strict=True):
            local = [i - sl.start for i in range(sl.start, sl.stop) if i in wanted]
            calls.append(actor.start_all.remote(local))
        infos: list[dict] = []
        for (obs, part), sl in zip(self._get_all(calls), self.slices, strict=True):
            self._obs[sl] = obs
            infos.extend(part)
        return infos

    def step_lists(self, actions):
        refs = [actor.step.remote(actions[sl]) for actor, sl in zip(self.actors, self.slices, strict=True)]
        results = self._get_all(refs)
        obs = np.concatenate([r[0] for r in results])
        self._obs[:] = obs
        rewards = np.concatenate([r[1] for r in results])
        terminated = np.concatenate([r[2] for r in results])
        truncated = np.concatenate([r[3] for r in results])
        infos = [info for r in results for info in r[4]]
        return obs, rewards, terminated, truncated, infos

    # -- a batch per call ------------------------------------------------------------------------
    def collect(self, order, rngs: list[np.random.Generator]) -> list:
        """Every actor's fragment of one batch: one broadcast (`order`) and one reply per actor."""
        self.send(order, rngs)
        return self.receive()

    def send(self, order, rngs: list[np.random.Generator]) -> None:
        """Order the next batch from every actor and return at once (`receive` gets it): with `train --overlap`
        the actors collect it while the learner updates on the last one."""
        import ray

        assert self._in_flight is None, "a batch is already on order"
        stats = BatchStats()
        self._batch += 1
        shared = ray.put(order)
        calls = zip(self.actors, self.slices, strict=True)
        self._in_flight = [a.collect.remote(shared, rngs[sl], self._batch) for a, sl in calls]
        stats.round_trips = len(self._in_flight)
        self.stats.append(stats)

    @property
    def in_flight(self) -> bool:
        return self._in_flight is not None

    def receive(self) -> list:
        """The fragments of the batch on order, in actor order; waits (with deadlines) for the slowest."""
        stats = self.stats[-1]
        t0 = time.perf_counter()
        fragments = self._get_all(self._in_flight, stats)  # on an error (a lost actor) it stays on order: `cancel`
        self._in_flight, self._received = None, stats
        stats.wait_s = time.perf_counter() - t0
        stats.collect_s = [f.collect_s for f in fragments]
        for f, sl in zip(fragments, self.slices, strict=True):
            self._obs[sl] = f.last_raw
        return fragments

    def cancel(self) -> None:
        """Drop the batch on order: each actor stops collecting it at its next observation. Its workers are then
        mid-step, so the next collection must start them afresh (`start_all`)."""
        import ray

        refs, self._in_flight = self._in_flight, None
        if refs is None:
            return
        for a in self.actors:
            a.stop.remote(self._batch)
        ray.wait(refs, num_returns=len(refs), timeout=self.answer_s)  # errors (stopped, lost) are the point

    def record_merge(self, seconds: float) -> dict[str, float]:
        """Note the learner's merge time of the batch last received; returns the scalars TensorBoard shows under
        `ray/` (the next batch may be on order already)."""
        last = self._received
        last.merge_s = seconds
        return {"ray/round_trips": last.round_trips, "ray/progress_checks": last.progress_checks,
                "ray/wait_s": last.wait_s, "ray/merge_s": seconds,
                "ray/actor_collect_s_max": max(last.collect_s, default=0.0)}  # fmt: skip

    # -- waiting, with deadlines -------------------------------------------------------------------
    def _get_all(self, refs: list, stats: BatchStats | None = None) -> list:
        """Every actor's answer, in actor order; never waits without a deadline."""
        import ray

        index = {ref: j for j, ref in enumerate(refs)}
        answers: dict[int, object] = {}
        pending = list(refs)
        last = {j: (-1, time.monotonic()) for j in range(len(refs))}  # (progress, when it last moved)
        while pending:
            done, pending = ray.wait(pending, num_returns=1, timeout=self.poll_s)
            for ref in done:
                answers[index[ref]] = self._answer(index[ref], ref)
            if not done:
                self._check_progress([index[r] for r in pending], last, stats)
        return [answers[j] for j in range(len(refs))]

    def _answer(self, j: int, ref):
        import ray

        try:
            return ray.get(ref, timeout=self.answer_s)
        except ray.exceptions.RayActorError as e:
            raise WorkerLostError(
                f"Ray actor {j} (workers {self._workers(j)}) on node {self.nodes[j] if self.nodes else '?'} "
                f"was lost: {str(e).splitlines()[0]}"
            ) from None
        except ray.exceptions.RayTaskError as e:
            cause = getattr(e, "cause", None)
            if isinstance(cause, EnergyPlusError | KeyboardInterrupt):
                raise cause from None
            raise

    def _check_progress(self, pending: list[int], last: dict, stats: BatchStats | None) -> None:
        import ray

        refs = [self.actors[j].progress.remote() for j in pending]
        if stats is not None:
            stats.progress_checks += len(refs)
        ready, _ = ray.wait(refs, num_returns=len(refs), timeout=self.answer_s)
        now = time.monotonic()
        for j, ref in zip(pending, refs, strict=True):
            if ref not in ready:
                raise WorkerLostError(
                    f"Ray actor {j} (workers {self._workers(j)}) on node {self.nodes[j]} did not answer "
                    f"a progress check within {self.answer_s:.0f} s"
                )
            served = self._answer(j, ref)
            if served != last[j][0]:
                last[j] = (served, now)
            elif now - last[j][1] > self.stall_s:
                raise WorkerLostError(
                    f"Ray actor {j} (workers {self._workers(j)}) on node {self.nodes[j]} served no observation "
                    f"for {now - last[j][1]:.0f} s"
                )

    def _workers(self, j: int) -> str:
        sl = self.slices[j]
        return f"{sl.start}-{sl.stop - 1}" if sl.stop - sl.start > 1 else str(sl.start)

    def close(self) -> None:
        """Stop every actor's collection, close its workers (EnergyPlus and pipes), then end the actors."""
        import ray

        self._in_flight = None
        if self.actors:
            for a in self.actors:
                a.stop.remote()  # a collection still running ends at its next observation
            refs = [a.close.remote() for a in self.actors]
            ready, _ = ray.wait(refs, num_returns=len(refs), timeout=60)
            for ref in ready:
                try:
                    ray.get(ref)
                except Exception as e:  # noqa: BLE001 - closing must not mask the original error
                    log.warning("closing Ray workers: %s", str(e).splitlines()[0])
            if len(ready) < len(refs):
                log.warning("%d Ray actor(s) did not close within 60 s; ending them", len(refs) - len(ready))
            for a in self.actors:
                ray.kill(a)
            self.actors = []
        if self._owns_ray and ray.is_initialized():
            ray.shutdown()
        # an actor lost mid-run (SIGKILL, OOM) ran no cleanup: its pipe directories on this node name a dead owner
        leftovers.sweep()


def _log_placement(nodes: list[str], slices: list[slice]) -> None:
    """The cluster's resources and how many workers each node got: what a user checks first on a cluster."""
    import ray

    res = ray.cluster_resources()
    alive = [n for n in ray.nodes() if n.get("Alive")]
    log.info("Ray cluster: %d node(s), %.0f CPUs, %.1f GiB memory", len(alive), res.get("CPU", 0),
             res.get("memory", 0) / 2**30)  # fmt: skip
    per_node: collections.Counter = collections.Counter()
    for node, sl in zip(nodes, slices, strict=True):
        per_node[node] += sl.stop - sl.start
    for node, n in per_node.items():
        log.info("  %s: %d worker(s)", node, n)
    log.info("Ray backend: %d workers in %d actors; a batch is one call per actor", sum(per_node.values()),
             len(slices))  # fmt: skip
