"""The node's side of the Ray backend: an actor that owns a group of EnergyPlus workers on its node.

Per batch it receives one order (the policy, the observation statistics, its workers' random
streams), collects its share of the batch with the pipelined loop and no call to the learner per
step, and returns one trajectory fragment (learning/fragments.py). The actor runs two threads, so
the learner can ask how far a collection has come (its deadline check) and stop it while it runs:
one batch's collection (`stop(batch)`, when the learner drops a batch it ordered ahead: `train --overlap`),
or every collection for good (`stop()`, closing).
"""

from __future__ import annotations

import logging
import socket
import threading
from dataclasses import replace

import numpy as np

from parallel_eplus.engine.config import SimulationConfig


def actor_class(max_concurrency: int = 2):
    """The Ray actor class (made on first use, so importing this module does not import Ray)."""
    import ray

    from parallel_eplus.envs.vector_env import EnergyPlusVectorEnv
    from parallel_eplus.learning.episode_keys import EpisodeKeys
    from parallel_eplus.learning.fragments import BatchOrder, Fragment, collect_fragment

    @ray.remote(max_concurrency=max_concurrency)
    class WorkerGroup:
        def __init__(self, config: SimulationConfig, shares: list[list[str]], first_worker: int, max_restarts: int):
            logging.basicConfig(level=logging.INFO)
            if config.spin_s is None:
                config = replace(config, spin_s=_node_spin_s(len(shares)))
            self.venv = EnergyPlusVectorEnv(config, shares, max_restarts=max_restarts, first_worker=first_worker)
            self.env = EpisodeKeys(self.venv)  # episode returns and SB3's info keys, as the learner's callbacks expect
            self.starts = np.ones(self.venv.num_envs, dtype=bool)
            self._lock = threading.Lock()  # one collection, step or close at a time
            self._closing = threading.Event()
            self._batch: tuple[int | None, threading.Event] = (None, threading.Event())  # the collection under way
            self._dropped: set[int] = set()  # batches the learner dropped, perhaps before they started here
            self.served = 0  # observations served so far: the learner's sign of life

        def start_all(self, indices):
            with self._lock:
                if len(list(indices)) == self.venv.num_envs:
                    self.env.reset()  # also zeroes the episode returns
                    self.starts[:] = True
                    infos = self.env.reset_infos
                else:
                    infos = self.venv.start_all(indices)
                return self.venv.observations(), infos

        def collect(self, order: BatchOrder, rngs: list[np.random.Generator], batch: int | None = None) -> Fragment:
            """This actor's share of batch `batch` (the learner's count; `stop(batch)` ends it early)."""
            with self._lock:
                stop = threading.Event()
                if self._closing.is_set() or batch in self._dropped:
                    stop.set()
                self._batch = (batch, stop)
                fragment = collect_fragment(self.env, order, self.venv.observations(), self.starts, rngs,
                                            stop, self._served)  # fmt: skip
                self.starts = fragment.last_starts.copy()
                return fragment

        def _served(self) -> None:
            self.served += 1

        def step(self, actions):
            with self._lock:
                return self.venv.step_lists(actions)

        def progress(self) -> int:
            return self.served

        def stop(self, batch: int | None = None) -> None:
            """End batch `batch`'s collection at its next observation (or before it starts); every one: None."""
            if batch is None:
                self._closing.set()
            else:
                self._dropped.add(batch)
            current, event = self._batch
            if batch is None or current == batch:
                event.set()

        def close(self) -> None:
            self._closing.set()
            self._batch[1].set()
            with self._lock:
                self.venv.close()

        def node(self) -> str:
            return f"{socket.gethostname()} ({ray.util.get_node_ip_address()})"

    return WorkerGroup


def _node_spin_s(workers: int) -> float:
    """Whether our reads may spin: only if the node has a core for every process a full node runs.

    A full node runs one EnergyPlus per CPU Ray offers there, plus one actor per `workers` of them; the
    vector env would count only this actor's own workers and spin where cores are short, taking them
    from EnergyPlus (measured: two one-worker actors spinning on a 2-core node ran at 0.6 of local).
    """
    import ray

    from parallel_eplus.engine.pipes import spin

    node = ray.get_runtime_context().get_node_id()
    cpus = next((n["Resources"].get("CPU", 0) for n in ray.nodes() if n["NodeID"] == node), 0)
    return spin.default_spin_s(int(cpus + -(-cpus // workers)))
