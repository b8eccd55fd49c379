"""Trajectory fragments: a batch's share collected where the workers are, shipped back in one reply.

With `--backend ray` each actor gets, once per batch, the policy (`NumpyPolicy`, a few kB), the
observation statistics and its workers' random streams; it runs the pipelined loop over its own
workers with no call to the learner per step, and returns a `Fragment`: the transitions as numpy
arrays, the value of where each worker stopped (so GAE is right across fragment ends), the episodes
that ended and the moments of the raw observations it saw. The learner merges fragments into SB3's
rollout buffer and `VecNormalize` (`rollout.py`) and runs the same update as with local workers.

Within a batch an actor normalizes with the statistics of the batch's start (the learner merges the
moments after it); the local loop updates them observation by observation. With fixed statistics the
two collect the same transitions (a test pins it).
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from parallel_eplus.learning.pipeline import SIDE_ARRAYS, SINK_ARRAYS, run_pipeline
from parallel_eplus.runs.numpy_policy import NumpyPolicy


@dataclass(frozen=True)
class ObsNormalizer:
    """`VecNormalize`'s observation normalization with frozen statistics (its `_normalize_obs`, as data)."""

    mean: np.ndarray
    var: np.ndarray
    epsilon: float
    clip: float

    @classmethod
    def of(cls, norm) -> ObsNormalizer | None:
        """A snapshot of a `VecNormalize`'s observation statistics; None when it does not normalize them."""
        if norm is None or not norm.norm_obs:
            return None
        return cls(norm.obs_rms.mean.copy(), norm.obs_rms.var.copy(), float(norm.epsilon), float(norm.clip_obs))

    def __call__(self, obs: np.ndarray) -> np.ndarray:
        return np.clip((obs - self.mean) / np.sqrt(self.var + self.epsilon), -self.clip, self.clip).astype(np.float32)


@dataclass(frozen=True)
class BatchOrder:
    """What the learner broadcasts once per batch: the same for every actor."""

    policy: NumpyPolicy
    normalizer: ObsNormalizer | None
    n_steps: int
    gamma: float
    bounds: tuple[np.ndarray, np.ndarray]  # the action space's low and high (actions are clipped to them)
    side: bool = False  # also each step's comfort cost and counts (pipeline.SIDE_ARRAYS): comfort is a constraint


@dataclass
class Fragment:
    """One actor's share of a batch, `[step, worker, ...]` like SB3's rollout buffer."""

    observations: np.ndarray
    actions: np.ndarray
    rewards: np.ndarray
    episode_starts: np.ndarray
    values: np.ndarray
    log_probs: np.ndarray
    dones: np.ndarray  # [step, worker]: the episode ended at this step
    ends: list[tuple[int, int, dict]] = field(default_factory=list)  # (step, worker, info) of every ended episode
    last_obs: np.ndarray | None = None  # where each worker stopped, as the policy sees it ...
    last_raw: np.ndarray | None = None  # ... and raw
    last_values: np.ndarray | None = None  # the critic's value there, for GAE across the fragment's end
    last_starts: np.ndarray | None = None  # whether each worker's last step ended its episode
    moments: tuple[np.ndarray, np.ndarray, int] | None = None  # mean, var, count of the raw observations seen
    rngs: list[np.random.Generator] = field(default_factory=list)  # each worker's stream, advanced
    collect_s: float = 0.0
    costs: np.ndarray | None = None  # with BatchOrder.side: pipeline.SIDE_ARRAYS
    comfort_out: np.ndarray | None = None
    comfort_zones: np.ndarray | None = None

    @classmethod
    def empty(
        cls, n_steps: int, n_workers: int, obs_shape: tuple[int, ...], n_actions: int, side: bool = False
    ) -> Fragment:
        shape = (n_steps, n_workers)
        f32 = np.float32
        extra = {name: np.zeros(shape, f32) for name, _ in SIDE_ARRAYS} if side else {}
        return cls(
            observations=np.zeros((*shape, *obs_shape), f32), actions=np.zeros((*shape, n_actions), f32),
            rewards=np.zeros(shape, f32), episode_starts=np.zeros(shape, f32), values=np.zeros(shape, f32),
            log_probs=np.zeros(shape, f32), dones=np.zeros(shape, bool), **extra,
        )  # fmt: skip


def collect_fragment(
    env,
    order: BatchOrder,
    raw: np.ndarray,
    starts: np.ndarray,
    rngs: list[np.random.Generator],
    stop: threading.Event | None = None,
    on_served: Callable[[], None] | None = None,
) -> Fragment:
    """Run the pipelined loop over `env`'s workers (an `EpisodeKeys` or `SB3VecEnv` stepping one by one) for one batch.

    `raw`: each worker's current raw observation; `starts`: whether its last step ended an episode.
    `stop` (set by another thread) ends the collection with KeyboardInterrupt: the learner is closing.
    """
    t0 = time.perf_counter()
    n = env.num_envs
    norm = order.normalizer
    raw = np.array(raw, dtype=np.float32)
    obs = norm(raw) if norm is not None else raw.copy()
    starts = np.array(starts, dtype=bool)
    fragment = Fragment.empty(order.n_steps, n, raw.shape[1:], order.bounds[0].shape[0], order.side)
    seen = np.zeros((order.n_steps * n, *raw.shape[1:]), np.float64)
    count = 0

    def observe(i: int, new_obs: np.ndarray) -> np.ndarray:
        nonlocal count
        if stop is not None and stop.is_set():
            raise KeyboardInterrupt("the learner is closing")
        raw[i] = new_obs
        seen[count] = new_obs
        count += 1
        if on_served is not None:
            on_served()
        return norm(new_obs) if norm is not None else new_obs

    t = 0

    def on_vector_step(infos: list[dict], dones: np.ndarray) -> bool:
        nonlocal t
        fragment.dones[t] = dones
        fragment.ends.extend((t, i, infos[i]) for i in np.flatnonzero(dones))
        t += 1
        return True

    run_pipeline(env, order.policy, fragment, order.n_steps, obs, starts, rngs, order.bounds, order.gamma,
                 observe, norm, on_vector_step)  # fmt: skip
    fragment.last_obs, fragment.last_raw, fragment.last_starts = obs, raw, starts
    fragment.last_values = order.policy.value(obs).astype(np.float32)
    if count:
        fragment.moments = (seen[:count].mean(axis=0), seen[:count].var(axis=0), count)
    fragment.rngs = rngs
    fragment.collect_s = time.perf_counter() - t0
    return fragment


def merge(buffer, fragments: list[Fragment], slices: list[slice]) -> None:
    """Each fragment into its workers' columns of SB3's rollout buffer."""
    for fragment, sl in zip(fragments, slices, strict=True):
        for name in SINK_ARRAYS:
            getattr(buffer, name)[:, sl] = getattr(fragment, name)
        for name, _ in SIDE_ARRAYS:  # comfort as a constraint: both have them
            if getattr(buffer, name, None) is not None and getattr(fragment, name) is not None:
                getattr(buffer, name)[:, sl] = getattr(fragment, name)
    buffer.pos, buffer.full = buffer.buffer_size, True
