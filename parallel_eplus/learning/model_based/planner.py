"""The planner: the cross-entropy method (CEM) over bounded increments of the last action, on the ensemble.

For every worker at once: `candidates` sequences of `horizon` increments (each within ±`max_increment` of the
normalized action, the action itself within [-1, 1]) are rolled out through every member of the ensemble in one
batched forward per horizon step (dynamics.py), scored, and the best `elites` refit the sampling distribution,
`iterations` times; the best sequence's first action is applied and the rest warm-starts the next step's search.

The cost of a step is the spec's energy term (every fuel, times the reward's `power_weight`: about 1 per step),
plus `comfort_weight` times the comfort surrogate of the constraint (learning/lagrangian.py: 0 inside each zone's
bounds shrunk by the margin, rising by 1 per margin beyond, here unbounded so the search is pushed back in), where
the band applies (the bounds: the spec's band, or each zone's thermostat schedules, dataset.py's `ComfortTimes`),
plus `disagreement_weight` times the members' spread of each zone temperature (K): the planner stays where the
model knows the building. Each member follows its own trajectory (PETS's "TS-inf").
"""

from __future__ import annotations

import time

import numpy as np
import torch as th

from parallel_eplus.learning.model_based.dynamics import Ensemble
from parallel_eplus.learning.model_based.settings import MPCSettings


class Planner:
    """CEM over action increments for `workers` workers, warm-started per worker."""

    def __init__(self, model: Ensemble, settings: MPCSettings, margin_c: float, power_weight: float, workers: int,
                 seed: int = 0):  # fmt: skip
        self.model, self.settings = model, settings
        self.margin = margin_c
        self.power_weight = power_weight
        self.n_temps = len(model.layout.temperatures)
        self.gen = th.Generator().manual_seed(seed)
        self.mean = th.zeros(workers, settings.horizon, model.layout.n_actions)
        self.support = (-th.ones(model.layout.n_actions), th.ones(model.layout.n_actions))  # `set_support`
        self.last_ms = 0.0
        self.last_cost = np.zeros(workers)

    def set_support(self, actions: np.ndarray) -> None:
        """Keep the actions within the range of each action in the data widened by `support_margin`: it can only
        grow (the data only grow), by up to the margin at each refit where the planner's own steps reach its edge."""
        if len(actions):
            m = self.settings.support_margin
            lo, hi = actions.min(axis=0), actions.max(axis=0)
            self.support = (th.as_tensor(np.maximum(lo - m, -1.0), dtype=th.float32),
                            th.as_tensor(np.minimum(hi + m, 1.0), dtype=th.float32))  # fmt: skip

    def reset(self, worker: int) -> None:
        """A new episode for `worker`: forget its warm start."""
        self.mean[worker] = 0.0

    @th.no_grad()
    def plan(self, s: np.ndarray, a_last: np.ndarray, exo: np.ndarray, applies: np.ndarray, bounds: np.ndarray,
             comfort_weight: float) -> np.ndarray:  # fmt: skip
        """Each worker's next action (normalized): s [W, n_state], a_last [W, A], exo [W, H, X], applies [W, H],
        each zone's comfort bounds bounds [W, H, K, 2]."""
        t0 = time.perf_counter()
        c = self.settings
        w, h, a_n = len(s), c.horizon, self.model.layout.n_actions
        n = c.candidates
        s_t, a_t = th.as_tensor(s, dtype=th.float32), th.as_tensor(a_last, dtype=th.float32)
        exo_t, app_t = th.as_tensor(exo, dtype=th.float32), th.as_tensor(applies, dtype=th.float32)
        bounds_t = th.as_tensor(np.asarray(bounds), dtype=th.float32)
        mean, std = self.mean.clone(), th.full((w, h, a_n), c.init_std)
        for _ in range(c.iterations):
            delta = mean[:, None] + std[:, None] * th.randn(w, n, h, a_n, generator=self.gen)
            delta[:, 0] = mean  # the warm start itself is always a candidate
            delta = delta.clamp(-c.max_increment, c.max_increment)
            actions = th.maximum(th.minimum(a_t[:, None, None, :] + delta.cumsum(2), self.support[1]), self.support[0])
            cost = self._cost(s_t, a_t, actions, exo_t, app_t, bounds_t, comfort_weight)  # [W, N]
            best = cost.argmin(1)
            elite = cost.topk(c.elites, dim=1, largest=False).indices
            chosen = delta.gather(1, elite[:, :, None, None].expand(-1, -1, h, a_n))
            mean, std = chosen.mean(1), chosen.std(1).clamp_min(0.01)
        rows = th.arange(w)
        first = actions[rows, best, 0]
        plan = actions[rows, best]
        steps = th.diff(th.cat([a_t[:, None], plan], dim=1), dim=1)
        self.mean = th.cat([steps[:, 1:], th.zeros(w, 1, a_n)], dim=1)  # shift the plan for the next step
        self.last_cost = cost[rows, best].numpy()
        self.last_ms = 1000 * (time.perf_counter() - t0)
        return first.numpy().astype(np.float32)

    def _cost(self, s, a_last, actions, exo, applies, bounds, comfort_weight: float) -> th.Tensor:
        """Each candidate's cost over the horizon: [W, N], from actions [W, N, H, A]."""
        w, n, h, a_n = actions.shape
        e, k = self.settings.members, self.n_temps
        state = s[:, None].expand(w, n, -1).reshape(1, w * n, -1).expand(e, -1, -1)
        a_prev = a_last[:, None].expand(w, n, a_n).reshape(w * n, a_n)
        total = th.zeros(w * n)
        for step in range(h):
            a = actions[:, :, step].reshape(w * n, a_n)
            x = exo[:, None, step].expand(w, n, -1).reshape(w * n, -1)
            state = self.model.step(state, a_prev, a, x)
            temps = state[..., :k]
            energy = state[..., k:].sum(-1) * self.power_weight  # [E, W*N]
            low = bounds[:, None, step, :, 0].expand(w, n, k).reshape(1, w * n, k)
            high = bounds[:, None, step, :, 1].expand(w, n, k).reshape(1, w * n, k)
            over = th.clamp(th.maximum(low + self.margin - temps, temps - high + self.margin), min=0)
            comfort = (over / self.margin).mean(-1) * applies[:, None, step].expand(w, n).reshape(1, w * n)
            spread = temps.std(0).sum(-1) if e > 1 else th.zeros(w * n)
            total += (energy + comfort_weight * comfort).mean(0) + self.settings.disagreement_weight * spread
            a_prev = a
        return total.reshape(w, n)
