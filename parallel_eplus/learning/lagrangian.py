"""Comfort as a constraint, not a weight: `train --comfort-target PCT`.

The learner minimises energy subject to the share of zone samples in band (where the band applies) staying at or
above the target. The env's reward then pays for energy only (`-power_weight × energy`); every step also reports
a comfort cost, and the learner pays `multiplier × cost` on top. The multiplier is a Lagrange multiplier adapted
from what each batch measured, as in PPO-Lagrangian (Ray, Achiam and Amodei 2019, "Benchmarking Safe
Exploration in Deep RL"), but in log space: after each batch

    multiplier *= ((out + floor) / (allowed + floor)) ** rate

where `out` is the batch's share of zone samples out of band and `allowed` is 100 - target (percentage points).
Dual ascent in the multiplier itself (and its PI refinement, Stooke et al. 2020) moves it by the target minus
the measured share. Near 100 % that error is lopsided: with a 99.6 % target a batch can beat it by at most 0.4
points but miss it by 99.6, so the bad batches of early learning wind the multiplier up and good batches unwind
it hundreds of times more slowly: on the data center it sat at its cap for 25 batches after the target was met,
leaving energy unpaid for. The ratio of measured to allowed violations is symmetric in log space: twice the
allowance raises the multiplier as much as half of it lowers it.

The cost is a surrogate that bounds the indicator from above, so keeping it low keeps the share in band high,
and it has a slope near the band's edges where an indicator has none: per zone, 0 inside the band shrunk by
`margin_c` on each side, rising linearly to 1 at the band's edge and 1 beyond (the edge the share in band
counts: the bounds widened by the spec's `tolerance`); a step's cost is the mean over its zones, 0 where the
band does not apply. The multiplier adapts to the measured share itself (the indicator),
which is what the target names.

Where the multiplier lives: on the model (`model.comfort`, a `Lagrangian`), so SB3 saves it in every checkpoint
and `--resume` restores it. On-policy (TRPO, PPO): each batch's rollout buffer holds the per-step costs and
counts (`ConstrainedRolloutBuffer`); before advantages are computed the multiplier is updated from the batch and
the batch's rewards pay it. Off-policy (SAC): the replay buffer stores each transition's cost and charges the
current multiplier when it samples (`CostReplayBuffer`), and `SACComfort` updates the multiplier every
`period` steps from the steps' infos.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np
from stable_baselines3.common.buffers import ReplayBuffer, RolloutBuffer
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.type_aliases import ReplayBufferSamples

from parallel_eplus.learning.pipeline import SIDE_ARRAYS, step_value
from parallel_eplus.learning.settings import ComfortConstraint

log = logging.getLogger(__name__)

# What a constrained step reports in `info` (engine/simulation.py); the buffers' arrays that hold it.
(_, COST), (_, OUT), (_, ZONES) = SIDE_ARRAYS


@dataclass
class Lagrangian:
    """The multiplier's state; saved with the model (`model.comfort`)."""

    settings: ComfortConstraint
    multiplier: float = 0.0
    measured_pct: float = float("nan")  # the last batch's share in band, where it applies
    allowed_pct: float = float("nan")  # the share out of band it was allowed (the planner's own level: own_level.py)
    updates: int = 0

    @classmethod
    def start(cls, settings: ComfortConstraint) -> Lagrangian:
        return cls(settings, settings.multiplier_init)

    def update(self, out: float, zones: float, allowed_pct: float | None = None) -> float:
        """The multiplier after a batch in which `out` of `zones` zone samples (where the band applied) left it;
        `allowed_pct`: the share out of band this batch may have (None: the target's, 100 - target)."""
        s = self.settings
        if zones <= 0:  # nothing to measure (an unoccupied stretch): hold
            return self.multiplier
        self.measured_pct = 100.0 * (1.0 - out / zones)
        self.allowed_pct = 100.0 - s.target_pct if allowed_pct is None else allowed_pct
        ratio = (100.0 - self.measured_pct + s.floor_pct) / (self.allowed_pct + s.floor_pct)
        self.multiplier = float(np.clip(self.multiplier * ratio**s.rate, s.multiplier_min, s.multiplier_max))
        self.updates += 1
        return self.multiplier

    def record(self, logger) -> None:
        logger.record("comfort/multiplier", self.multiplier)
        logger.record("comfort/in_band_pct", self.measured_pct)
        logger.record("comfort/target_pct", self.settings.target_pct)
        logger.record("comfort/allowed_out_pct", self.allowed_pct)


def comfort_of(model) -> Lagrangian | None:
    return getattr(model, "comfort", None)


class ConstrainedRolloutBuffer(RolloutBuffer):
    """SB3's rollout buffer with each transition's comfort cost and counts (filled by the rollout loops)."""

    def reset(self) -> None:
        shape = (self.buffer_size, self.n_envs)
        self.costs = np.zeros(shape, np.float32)
        self.comfort_out = np.zeros(shape, np.float32)
        self.comfort_zones = np.zeros(shape, np.float32)
        super().reset()

    def record_infos(self, row: int, infos: list[dict]) -> None:
        """Row `row`'s costs and counts from the vector step's infos (the lockstep loop)."""
        for name, key in SIDE_ARRAYS:
            getattr(self, name)[row] = [step_value(info, key) for info in infos]

    def charge(self, lagrangian: Lagrangian, logger) -> None:
        """Update the multiplier from this batch, then make the batch's rewards pay it."""
        lagrangian.update(float(self.comfort_out.sum()), float(self.comfort_zones.sum()))
        self.rewards -= lagrangian.multiplier * self.costs
        lagrangian.record(logger)
        logger.record("comfort/cost_mean", float(self.costs.mean()))


class CostReplayBuffer(ReplayBuffer):
    """SB3's replay buffer that keeps each transition's comfort cost and charges the current multiplier when it
    samples (set by `SACComfort`): old transitions pay today's price of comfort."""

    multiplier: float = 0.0

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self.costs = np.zeros((self.buffer_size, self.n_envs), dtype=np.float32)

    def add(self, obs, next_obs, action, reward, done, infos) -> None:
        self.costs[self.pos] = [step_value(info, COST) for info in infos]
        super().add(obs, next_obs, action, reward, done, infos)

    def _get_samples(self, batch_inds: np.ndarray, env=None) -> ReplayBufferSamples:
        """SB3's sampling (one random worker per row) with the rewards net of `multiplier × cost`."""
        envs = np.random.randint(0, high=self.n_envs, size=(len(batch_inds),))
        if self.optimize_memory_usage:
            next_obs = self.observations[(batch_inds + 1) % self.buffer_size, envs, :]
        else:
            next_obs = self.next_observations[batch_inds, envs, :]
        rewards = self.rewards[batch_inds, envs] - self.multiplier * self.costs[batch_inds, envs]
        data = (
            self._normalize_obs(self.observations[batch_inds, envs, :], env),
            self.actions[batch_inds, envs, :],
            self._normalize_obs(next_obs, env),
            (self.dones[batch_inds, envs] * (1 - self.timeouts[batch_inds, envs])).reshape(-1, 1),
            self._normalize_reward(rewards.reshape(-1, 1), env),
        )
        return ReplayBufferSamples(*tuple(map(self.to_torch, data)))


class SACComfort(BaseCallback):
    """SAC's multiplier: counted from every step's info, updated every `period` env steps."""

    def __init__(self, period: int):
        super().__init__()
        self.period = period
        self._out = self._zones = 0.0
        self._steps = 0

    def _on_training_start(self) -> None:
        self.model.replay_buffer.multiplier = comfort_of(self.model).multiplier

    def _on_step(self) -> bool:
        for info in self.locals["infos"]:
            self._out += step_value(info, OUT)
            self._zones += step_value(info, ZONES)
        self._steps += len(self.locals["infos"])
        if self._steps >= self.period:
            lagrangian = comfort_of(self.model)
            lagrangian.update(self._out, self._zones)
            self.model.replay_buffer.multiplier = lagrangian.multiplier
            lagrangian.record(self.logger)
            self._out = self._zones = 0.0
            self._steps = 0
        return True
