"""The learner's side of a control step: SB3's rollout loop with the policy evaluated in numpy.

The policy runs as a `NumpyPolicy` snapshot (numpy_policy.py: 0.36 ms of learner CPU per vector step
against SB3's 0.93 ms). Everything else is SB3's: the rollout buffer, the timeout bootstrap, the
callbacks and the algorithm's update, which still runs in torch.

With Ray actors the loop runs where the workers are: one order out and one trajectory fragment back
per actor and batch (fragments.py), instead of a call per step. With `overlap` (`train --overlap`) the
next batch is ordered before the update on this one, so the workers collect while the learner updates
(overlap.py: locally the same fragment loop runs in a thread).

With local workers the loop is also pipelined (pipeline.py): each worker gets its next action as soon
as its own observation arrives, instead of every worker waiting for the slowest at every step (SB3's
lockstep `VecEnv`). Each worker fills its own column of the buffer; callbacks still see whole vector
steps.
Each worker draws its exploration noise from a stream of its own, so with fixed observation
statistics both loops collect the same rollout. The price of pipelining: the running statistics are
updated in the order workers are served, which depends on timing, so a seed no longer fixes a
training run bit for bit (`lockstep = True` does).
"""

from __future__ import annotations

import time

import numpy as np
import torch as th
from stable_baselines3.common.buffers import RolloutBuffer
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.vec_env import VecEnv, VecNormalize

from parallel_eplus.learning import fragments
from parallel_eplus.learning.overlap import IdleClock, LocalCollector, TimedReady
from parallel_eplus.learning.pipeline import run_pipeline
from parallel_eplus.learning.sb3_adapter import SB3VecEnv
from parallel_eplus.runs.numpy_policy import NumpyPolicy


def _pipelinable(env: VecEnv) -> tuple[SB3VecEnv | None, VecNormalize | None]:
    """Our workers, and the observation normalization over them, when they can be stepped one by one (local)
    or collect fragments themselves (Ray). One worker too: the loop is SB3's, minus `VecNormalize`'s per-row
    `np.var` and copies, which a lone worker's EnergyPlus waits for at every step."""
    norm = None
    if isinstance(env, VecNormalize) and not env.norm_reward and not isinstance(env.obs_rms, dict):
        norm, env = env, env.venv
    if isinstance(env, SB3VecEnv) and (env.collects_fragments or env.steps_one_by_one):
        return env, norm
    return None, None


class NumpyRollouts:
    """For SB3's on-policy algorithms: collect rollouts with a `NumpyPolicy` when the policy has its shape.

    Saved models are the algorithm's ordinary models: `sb3_contrib.TRPO.load` (or `PPO.load`) reads them.
    """

    lockstep = False  # True: step every worker together, as SB3 does (a seed then fixes the run bit for bit)
    overlap = False  # True: collect the next batch while updating on this one (overlap.py)
    _idle: IdleClock | None = None
    _local: LocalCollector | None = None  # with `overlap`, the local workers' collection thread (per `learn`)
    _ordered_from = None  # the collector holding the batch on order, if any

    def learn(self, *args, **kwargs):
        self._idle = IdleClock()
        try:
            return super().learn(*args, **kwargs)
        finally:
            self._drop_order()

    def _drop_order(self) -> None:
        """A batch ordered ahead and not used (the run stopped or failed): stop its collection. Its workers are
        then mid-step, so the next `learn` starts them afresh (as SB3 does when there is no last observation)."""
        collector, self._ordered_from, self._local = self._ordered_from, None, None
        if collector is not None and collector.in_flight:
            collector.cancel()
            self._last_obs = None

    def set_random_seed(self, seed: int | None = None) -> None:
        super().set_random_seed(seed)  # SB3 calls this while setting the model up, seed or not
        # One stream per worker: its draws then do not depend on the order workers are served in. A
        # resumed run (SB3 restores num_timesteps first) draws afresh rather than replaying its start.
        entropy = None if seed is None else [seed, self.num_timesteps]
        self._rngs = [np.random.default_rng(s) for s in np.random.SeedSequence(entropy).spawn(self.n_envs)]

    def _excluded_save_params(self) -> list[str]:
        return [*super()._excluded_save_params(), "_rngs", "lockstep", "overlap", "_idle", "_local", "_ordered_from"]

    def _charge_comfort(self, buffer: RolloutBuffer) -> None:
        """Comfort as a constraint (`model.comfort`): update the multiplier from the batch, charge its rewards."""
        lagrangian = getattr(self, "comfort", None)
        if lagrangian is not None:
            buffer.charge(lagrangian, self.logger)

    def collect_rollouts(
        self, env: VecEnv, callback: BaseCallback, rollout_buffer: RolloutBuffer, n_rollout_steps: int
    ) -> bool:
        if not NumpyPolicy.supports(self.policy):
            return super().collect_rollouts(env, callback, rollout_buffer, n_rollout_steps)
        assert self._last_obs is not None, "No previous observation was provided"
        self.policy.set_training_mode(False)
        policy = NumpyPolicy(self.policy, self.sde_sample_freq)
        workers, norm = (None, None) if self.lockstep else _pipelinable(env)
        if workers is not None:
            return self._collect_pipelined(policy, workers, norm, callback, rollout_buffer, n_rollout_steps)
        low, high = self.action_space.low, self.action_space.high
        rollout_buffer.reset()
        callback.on_rollout_start()
        for _ in range(n_rollout_steps):
            actions, values, log_probs = policy.sample(self._last_obs, self._rngs)
            clipped_actions = np.clip(actions, low, high)  # the buffer keeps the unclipped ones, as in SB3
            new_obs, rewards, dones, infos = env.step(clipped_actions)
            self.num_timesteps += env.num_envs
            callback.update_locals(locals())
            if not callback.on_step():
                return False
            self._update_info_buffer(infos, dones)
            # A cut (not finished) episode: bootstrap with the value of where it stopped (SB3 issue #633).
            for i in np.flatnonzero(dones):
                terminal = infos[i].get("terminal_observation")
                if terminal is not None and infos[i].get("TimeLimit.truncated", False):
                    rewards[i] += self.gamma * policy.value(terminal[None])[0]
            rollout_buffer.add(
                self._last_obs, actions, rewards, self._last_episode_starts,
                th.from_numpy(values), th.from_numpy(log_probs),
            )  # fmt: skip
            if hasattr(rollout_buffer, "record_infos"):  # comfort as a constraint: the step's cost and counts
                rollout_buffer.record_infos(rollout_buffer.pos - 1, infos)
            self._last_obs = new_obs
            self._last_episode_starts = dones
        values = th.from_numpy(policy.value(new_obs))
        self._charge_comfort(rollout_buffer)
        rollout_buffer.compute_returns_and_advantage(last_values=values, dones=dones)
        callback.update_locals(locals())
        callback.on_rollout_end()
        return True

    def _collect_pipelined(
        self, policy: NumpyPolicy, env: SB3VecEnv, norm: VecNormalize | None, callback: BaseCallback,
        buffer: RolloutBuffer, n_steps: int,
    ) -> bool:  # fmt: skip
        """`collect_rollouts`, serving each worker as soon as its observation arrives (here or in Ray actors).

        Worker i's t-th transition goes to row t, column i of the buffer, as in the lockstep loop. Once
        every worker has made step t, the callbacks see that vector step whole. Of `VecNormalize.step_wait`
        this does what a run with `norm_reward=False` uses: the observation statistics, not the returns'.
        """
        assert n_steps == buffer.buffer_size
        finished = False
        # With `overlap`, a learn's first local batch runs here (its statistics updated observation by observation,
        # as without overlap); it orders the next, which the workers collect as a fragment during the update.
        ahead = self._ordered_from is not None
        collect = self._collect_fragments if env.collects_fragments or ahead else self._pipeline
        try:
            finished = collect(policy, env, norm, callback, buffer, n_steps)
            return finished
        finally:
            if not finished:  # stopped or failed with workers mid-step: the next `learn` must start
                self._last_obs = None  # them afresh, which SB3 does when there is no last observation

    def _pipeline(
        self, policy: NumpyPolicy, env: SB3VecEnv, norm: VecNormalize | None, callback: BaseCallback,
        buffer: RolloutBuffer, n_steps: int,
    ) -> bool:  # fmt: skip
        n = env.num_envs
        obs = np.array(self._last_obs)  # normalized, as the policy sees it
        raw = np.array(norm.old_obs if norm is not None else obs)
        starts = np.array(self._last_episode_starts, dtype=bool)  # worker i's last `done`
        normalizing = norm is not None and norm.norm_obs
        buffer.reset()
        callback.on_rollout_start()
        self._record(self._idle.ordered() if self._idle is not None else {})
        t0, timed = time.perf_counter(), TimedReady(env)

        def observe(i: int, new_obs: np.ndarray) -> np.ndarray:
            raw[i] = new_obs
            if not normalizing:
                return new_obs
            # `VecNormalize.step_wait` on one row, minus the fixed costs that made it the learner's
            # largest per-step item: a row's mean is itself and its variance 0 (what `update` would
            # reduce to, bit for bit), and `normalize_obs` would deep-copy the row first.
            if norm.training:
                norm.obs_rms.update_from_moments(new_obs, 0.0, 1)
            return norm._normalize_obs(new_obs, norm.obs_rms).astype(np.float32)

        def on_vector_step(infos: list[dict], dones: np.ndarray) -> bool:
            self.num_timesteps += n
            callback.update_locals({"infos": infos, "dones": dones})
            if not callback.on_step():
                return False
            self._update_info_buffer(infos, dones)
            return True

        bounds = (self.action_space.low, self.action_space.high)
        if not run_pipeline(timed, policy, buffer, n_steps, obs, starts, self._rngs, bounds, self.gamma, observe,
                            norm.normalize_obs if normalizing else None, on_vector_step):  # fmt: skip
            return False
        if self._idle is not None:  # the learner serves the workers here: it is idle while it waits on them
            self._idle.collected(timed.waited_s, time.perf_counter() - t0)
        buffer.pos, buffer.full = n_steps, True
        self._last_obs, self._last_episode_starts = obs, starts
        if norm is not None:
            norm.old_obs = raw
        if self.overlap and self.num_timesteps < self._total_timesteps:
            self._order(self._collector(env, norm), policy, norm, n_steps, buffer)  # collected during this update
        values = th.from_numpy(policy.value(obs))
        self._charge_comfort(buffer)
        buffer.compute_returns_and_advantage(last_values=values, dones=starts)
        callback.update_locals({"new_obs": obs, "dones": starts, "values": values})
        callback.on_rollout_end()
        return True

    def _record(self, scalars: dict[str, float]) -> None:
        for key, value in scalars.items():
            self.logger.record(key, value)

    def _collector(self, env: SB3VecEnv, norm: VecNormalize | None):
        """Where fragments come from: the Ray actors, or (`overlap`) a thread over the local workers."""
        if env.collects_fragments:
            return env.venv
        if self._local is None:
            raw = norm.old_obs if norm is not None else self._last_obs
            self._local = LocalCollector(env, raw, self._last_episode_starts)
        return self._local

    def _order(self, collector, policy: NumpyPolicy, norm: VecNormalize | None, n_steps: int, buffer) -> None:
        """Send a batch's order: this policy, the statistics as they are now, each worker's random stream."""
        if self._idle is not None:
            self._record(self._idle.ordered())
        order = fragments.BatchOrder(policy, fragments.ObsNormalizer.of(norm), n_steps, self.gamma,
                                     (self.action_space.low, self.action_space.high),
                                     getattr(buffer, "costs", None) is not None)  # fmt: skip
        collector.send(order, self._rngs)
        self._ordered_from = collector

    def _collect_fragments(
        self, policy: NumpyPolicy, env: SB3VecEnv, norm: VecNormalize | None, callback: BaseCallback,
        buffer: RolloutBuffer, n_steps: int,
    ) -> bool:  # fmt: skip
        """`collect_rollouts` from trajectory fragments: Ray actors' (one order out and one fragment back per
        actor, fragments.py), or with `overlap` the local workers' collected in a thread (overlap.py).

        With `overlap` the next batch is ordered before this one's update. The callbacks then see the batch's
        vector steps in order, as with the local loop.
        """
        collector = self._collector(env, norm)
        buffer.reset()
        callback.on_rollout_start()
        ahead = collector.in_flight  # ordered during the last update, by the policy before it
        if not ahead:
            self._order(collector, policy, norm, n_steps, buffer)
        t0 = time.perf_counter()
        parts = collector.receive()
        t1 = time.perf_counter()
        self._ordered_from = None
        if self._idle is not None:
            self._idle.collected(t1 - t0, float(np.mean([p.collect_s for p in parts])))
        fragments.merge(buffer, parts, collector.slices)
        for part, sl in zip(parts, collector.slices, strict=True):
            self._rngs[sl] = part.rngs
            if norm is not None and norm.norm_obs and norm.training and part.moments is not None:
                norm.obs_rms.update_from_moments(*part.moments)
        cat = np.concatenate
        obs, starts = cat([p.last_obs for p in parts]), cat([p.last_starts for p in parts])
        self._last_obs, self._last_episode_starts = obs, starts
        if norm is not None:
            norm.old_obs = cat([p.last_raw for p in parts])
        n = env.num_envs
        if self.overlap and self.num_timesteps + n * n_steps < self._total_timesteps:
            self._order(collector, policy, norm, n_steps, buffer)  # the next batch, collected during this update
        last_values = cat([p.last_values for p in parts])
        if ahead:  # collected by the policy before the last update: the current critic values it
            flat = buffer.observations.reshape(n_steps * n, *buffer.observations.shape[2:])
            buffer.values[:] = policy.value(flat).reshape(n_steps, n)
            last_values = policy.value(obs).astype(np.float32)
        values = th.from_numpy(last_values)
        self._charge_comfort(buffer)
        buffer.compute_returns_and_advantage(last_values=values, dones=starts)
        dones = cat([p.dones for p in parts], axis=1)
        ends: dict[int, list[tuple[int, dict]]] = {}
        for part, sl in zip(parts, collector.slices, strict=True):
            for t, i, info in part.ends:
                ends.setdefault(t, []).append((sl.start + i, info))
        for t in range(n_steps):
            infos: list[dict] = [{} for _ in range(n)]
            for i, info in ends.get(t, ()):
                infos[i] = info
            self.num_timesteps += n
            callback.update_locals({"infos": infos, "dones": dones[t]})
            if not callback.on_step():
                return False
            self._update_info_buffer(infos, dones[t])
        if env.collects_fragments:
            self._record(collector.record_merge(time.perf_counter() - t1))
        callback.update_locals({"new_obs": obs, "dones": starts, "values": values})
        callback.on_rollout_end()
        return True
