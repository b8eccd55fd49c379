"""Collection overlapped with the update (`train --overlap`): the workers collect batch k+1 while the learner
updates on batch k, and the idle shares that show what that buys.

Without it every worker waits while the learner updates (1.3 s per 16k batch on 2 cores; on a cluster the update
caps throughput near B / U however many workers are added: docs/cluster.md). With it the learner orders batch
k+1 (the policy as numpy arrays, the observation statistics, each worker's random stream: fragments.BatchOrder)
right after merging batch k and before updating on it, so batch k+1 is collected by the policy the update on
batch k starts from, and reaches the learner one update later. What that changes (rollout.py):

- the buffer's log-probabilities are the behaviour policy's, so the algorithms' importance ratio
  pi_theta(a|s) / pi_behaviour(a|s) weights the one-policy-old actions (TRPO's surrogate, PPO's clipped ratio);
- the critic's values (GAE's baseline, and the returns the critic is fitted to) are re-evaluated by the current
  critic before the advantages are computed, as if it had collected the batch.

Locally the workers collect in a thread of the learner's process (`LocalCollector`), with the loop a Ray actor
runs (fragments.collect_fragment); with `--backend ray` the actors do (learning/ray_vector_env.py). Both offer
`send(order, rngs)` (returns at once), `receive()` (the fragments; raises what the collection raised) and
`cancel()` (drop the batch on order: its workers are then mid-step and must start afresh).
"""

from __future__ import annotations

import threading
import time

import numpy as np

from parallel_eplus.learning.fragments import BatchOrder, Fragment, collect_fragment


class LocalCollector:
    """The learner's own workers (an `SB3VecEnv` stepping one by one) collecting a batch in a thread.

    The loop mostly waits on pipes (`select`), and torch releases the GIL inside each operation of the update,
    so the two share the process with little contention.
    """

    def __init__(self, env, raw: np.ndarray, starts: np.ndarray):
        """`raw`: each worker's current raw observation; `starts`: whether its last step ended an episode."""
        self.env = env
        self.slices = [slice(0, env.num_envs)]
        self._raw, self._starts = np.array(raw, dtype=np.float32), np.array(starts, dtype=bool)
        self._thread: threading.Thread | None = None
        self._stop = threading.Event()
        self._result: Fragment | BaseException | None = None

    @property
    def in_flight(self) -> bool:
        return self._thread is not None

    def send(self, order: BatchOrder, rngs: list[np.random.Generator]) -> None:
        assert self._thread is None, "a batch is already on order"
        self._stop, self._result = threading.Event(), None
        raw, starts, stop = self._raw, self._starts, self._stop

        def run() -> None:
            try:
                self._result = collect_fragment(self.env, order, raw, starts, list(rngs), stop)
            except BaseException as e:  # noqa: BLE001 - `receive` raises it in the learner
                self._result = e

        self._thread = threading.Thread(target=run, name="parallel-eplus-collect", daemon=True)
        self._thread.start()

    def receive(self) -> list[Fragment]:
        while self._thread.is_alive():
            self._thread.join(0.2)  # a short wait at a time: Ctrl-C reaches the learner at once
        self._thread, result = None, self._result
        if isinstance(result, BaseException):
            raise result
        self._raw, self._starts = result.last_raw, result.last_starts
        return [result]

    def cancel(self) -> None:
        """Stop the batch on order at its next observation (a hung worker: at its step deadline), and wait."""
        if self._thread is None:
            return
        self._stop.set()
        self._thread.join()
        self._thread = None


class IdleClock:
    """Each batch's cycle, from its order to the next batch's: the share the learner waited for the workers, and
    the share the workers had nothing to collect (they wait while the learner merges and, without overlap,
    updates). Known when the next batch is ordered; TensorBoard shows them under `throughput/`."""

    def __init__(self):
        self._t: float | None = None
        self._wait_s = self._collect_s = None

    def ordered(self) -> dict[str, float]:
        """A batch goes out now; returns the previous batch's shares (none for a learn's first)."""
        now = time.perf_counter()
        shares = {}
        if self._t is not None and self._collect_s is not None and now > self._t:
            cycle = now - self._t
            shares = {
                "throughput/learner_idle_share": min(self._wait_s / cycle, 1.0),
                "throughput/workers_idle_share": max(1.0 - self._collect_s / cycle, 0.0),
                "throughput/cycle_s": cycle,
            }
        self._t, self._wait_s, self._collect_s = now, None, None
        return shares

    def collected(self, wait_s: float, collect_s: float) -> None:
        """The batch is in: the learner waited `wait_s` for it; the workers collected for `collect_s` (a mean)."""
        self._wait_s, self._collect_s = wait_s, collect_s


class TimedReady:
    """A vector env whose `ready` adds up the time the caller waits in it (the local loop's learner, idle)."""

    def __init__(self, env):
        self.env = env
        self.num_envs = env.num_envs
        self.send_one, self.receive_one = env.send_one, env.receive_one
        self.waited_s = 0.0

    def ready(self, indices) -> list[int]:
        t0 = time.perf_counter()
        try:
            return self.env.ready(indices)
        finally:
            self.waited_s += time.perf_counter() - t0
