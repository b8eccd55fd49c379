"""The planner: the cross-entropy method (CEM) over bounded increments of the last action, on the ensemble.

For every worker at once: `candidates` sequences of `horizon` increments (each within ±`max_increment` of the
normalized action, the action itself within the data's support) are rolled out through every member of the
ensemble in one call per horizon step (ensemble_graph.py), scored, and the best `elites` refit the sampling
distribution, `iterations` times; the best sequence's first action is applied and the rest (`Plan.increments`)
warm-starts the next step's search.

The cost of a step is the spec's energy term (every fuel, times the reward's `power_weight`: about 1 per step;
under another objective each predicted part weighed as the reward weighs it at that step, energy_weights.py),
plus `comfort_weight` times the comfort surrogate of the constraint (learning/lagrangian.py: 0 inside each zone's
bounds shrunk by the margin, rising by 1 per margin beyond, here unbounded so the search is pushed back in), where
the band applies (the bounds: the spec's band, or each zone's thermostat schedules, calendar.py),
plus `disagreement_weight` times the members' spread of each zone temperature (K): the planner stays where the
model knows the building. Each member follows its own trajectory (PETS's "TS-inf"); the comfort term is the
members' mean, or with `comfort_risk = "worst"` the worst member's (a chance constraint: the band held by every
member's prediction, not by their average); `terminal_weight` weighs the horizon's last step's comfort more (a
plan must not end at the band's edge, where the next plan has no room). Measured against the building's own plan
(`reference`), `own_radius` keeps its thermostats near that plan and `min_saving` plays it unless the search's plan
is predicted to save that share: the model knows the building only near what it has seen, and the best of hundreds
of candidates is the one its errors favour most.

Numpy and onnxruntime only, and a function of its arguments: the sampler is seeded per decision from what the
decision sees (`decision_seed`), so a served planner answers a request exactly as the in-process one acts.
"""

from __future__ import annotations

import hashlib
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from parallel_eplus.learning.model_based.runtime.demand import DemandOutlook

Forward = Callable[[np.ndarray], np.ndarray]  # [members, batch, inputs] -> [members, batch, targets], physical


@dataclass(frozen=True)
class Plan:
    """One decision per worker: the action to apply, the rest of the plan (the next warm start), its cost, and the
    members' largest spread of a zone temperature along it (K), which the served planner's fallback reads."""

    action: np.ndarray  # [W, A], normalized
    increments: np.ndarray  # [W, H, A]: the plan's increments from the next step on, a zero step appended
    cost: np.ndarray  # [W]
    spread_k: np.ndarray  # [W]
    ms: float
    own_action: np.ndarray | None = None  # [W, A]: the own plan's first action, as a candidate plays it (with `hold`)
    own_next: np.ndarray | None = None  # [W, K]: the members' mean zone temperatures after it


def decision_seed(seed: int, when: str, state: np.ndarray) -> int:
    """A sampler seed from what one decision sees: its time and state (float32 bytes, which a reading survives
    through JSON exactly; the last action, sent back in physical units, need not)."""
    h = hashlib.blake2b(digest_size=8)
    h.update(f"{seed}|{when}".encode())
    h.update(np.ascontiguousarray(state, np.float32).tobytes())
    return int.from_bytes(h.digest(), "little")


def _ahead(applies: np.ndarray, lead: int) -> np.ndarray:
    """[W, H]: where the band applies within the next `lead` steps (the horizon's end treated as outside)."""
    if lead <= 0:
        return applies
    padded = np.pad(applies, ((0, 0), (0, lead)))
    return np.lib.stride_tricks.sliding_window_view(padded, lead + 1, axis=1).any(-1)


def side_array(sides: list[tuple[int, int] | None]) -> np.ndarray:
    """[A]: each action's thermostat side as `Planner.plan` reads it (0 lower, 1 upper, -1 not a thermostat), from
    `thermostat_sides` (control.py; the served planner's contract)."""
    return np.array([-1 if side is None else side[1] for side in sides], int)


def _follow(a_last: np.ndarray, target: np.ndarray, max_increment: float, low: np.ndarray,
            high: np.ndarray) -> np.ndarray:  # fmt: skip
    """The path [W, H, A] that moves from `a_last` [W, A] toward `target` [W, H, A] by at most `max_increment` a
    step, within the support: what a candidate can make of the target (a jump it cannot make at once, it makes up
    over the next steps)."""
    path, x = np.empty_like(target), np.asarray(a_last, np.float32)
    for t in range(target.shape[1]):
        x = np.clip(x + np.clip(target[:, t] - x, -max_increment, max_increment), low, high)
        path[:, t] = x
    return path


class Planner:
    """CEM over action increments; `settings` is an MPCSettings (or anything with its planner fields)."""

    def __init__(self, forward: Forward, members: int, n_temps: int, settings, margin_c: float, power_weight: float):
        self.forward, self.members, self.n_temps, self.settings = forward, members, n_temps, settings
        self.margin, self.power_weight = margin_c, power_weight

    def plan(self, s: np.ndarray, a_last: np.ndarray, exo: np.ndarray, applies: np.ndarray, bounds: np.ndarray,
             comfort_weight: float, support: tuple[np.ndarray, np.ndarray], warm: np.ndarray,
             seeds: list[int], energy_weights: np.ndarray | None = None,
             reference: np.ndarray | None = None, demand: DemandOutlook | None = None,
             follows: np.ndarray | None = None, hold: np.ndarray | None = None,
             sides: np.ndarray | None = None) -> Plan:  # fmt: skip
        """s [W, n_state], a_last [W, A], exo [W, H, X], applies [W, H], each zone's bounds [W, H, K, 2], the
        actions' support (low [A], high [A]), the warm start [W, H, A], one sampler seed per worker, the
        weights of the predicted energy parts [W, H, P] (None: each counts once), and the actions [W, H, A] whose
        predicted discomfort is free (`comfort_reference = "own"`; None: every K beyond the bounds costs); the
        reference is itself a candidate, so the search can always fall back on it; `demand`: the demand charges
        over the horizon (demand.py), None: none priced; `follows` [A]: the actions the reference sets (the
        thermostats), which `own_radius` keeps near it; `hold` [W]: the workers that play the reference
        (guard.py); `sides` [A]: which bound each thermostat action's own setpoint is (0 the lower: heating, 1 the
        upper: cooling, -1 not a thermostat), which `band_thermostats` holds to the own plan where the band
        applies."""
        t0 = time.perf_counter()
        c = self.settings
        w, h, a_n = len(s), c.horizon, a_last.shape[1]
        s, a_last = np.asarray(s, np.float32), np.asarray(a_last, np.float32)
        low, high = (np.asarray(b, np.float32) for b in support)
        if reference is not None:  # as a candidate can follow it: within the support, ±max_increment a step
            reference = _follow(a_last, np.asarray(reference, np.float32), c.max_increment, low, high)
        near = None
        radius = getattr(c, "own_radius", None)
        if reference is not None and radius is not None and follows is not None:  # [W, 1, H, A] each side
            r = np.where(np.asarray(follows, bool), np.float32(radius), np.float32(np.inf))
            near = (reference[:, None] - r, reference[:, None] + r)
        band = getattr(c, "band_thermostats", "free")
        if reference is not None and band != "free" and sides is not None:
            inside = _ahead(np.asarray(applies) > 0, getattr(c, "band_lead", 0))[:, None, :, None]  # [W, 1, H, 1]
            sides, exact = np.asarray(sides), band == "own"
            low_ = np.where(inside & ((sides == 0) | exact & (sides >= 0)), reference[:, None], -np.inf)  # heating
            high_ = np.where(inside & ((sides == 1) | exact & (sides >= 0)), reference[:, None], np.inf)  # cooling
            near = (low_, high_) if near is None else (np.maximum(near[0], low_), np.minimum(near[1], high_))
        rngs = [np.random.default_rng(seed) for seed in seeds]
        mean, std = np.asarray(warm, np.float32).copy(), np.full((w, h, a_n), c.init_std, np.float32)
        for i in range(c.iterations):
            # each iteration searches a narrower distribution: `shrink` of the last one's candidates and elites
            n = max(int(round(c.candidates * c.shrink**i)), 2)
            elites = max(int(round(c.elites * c.shrink**i)), 2)
            noise = np.stack([r.standard_normal((n, h, a_n), np.float32) for r in rngs])
            delta = mean[:, None] + std[:, None] * noise
            delta[:, 0] = mean  # the warm start itself is always a candidate
            if reference is not None:  # and so is the reference: the own thermostats' plan, as far as it can be
                delta[:, 1] = np.diff(np.concatenate([a_last[:, None], reference], axis=1), axis=1)
            np.clip(delta, -c.max_increment, c.max_increment, out=delta)
            actions = np.clip(a_last[:, None, None, :] + np.cumsum(delta, axis=2), low, high)
            if near is not None:
                np.clip(actions, *near, out=actions)
            cost, spread = self._cost(s, a_last, actions, exo, applies, bounds, comfort_weight, energy_weights,
                                      reference, demand)  # fmt: skip
            elite = np.argpartition(cost, elites - 1, axis=1)[:, :elites]
            chosen = np.take_along_axis(delta, elite[:, :, None, None], axis=1)
            mean, std = chosen.mean(1), np.maximum(chosen.std(1, ddof=1), 0.01)
        rows = np.arange(w)
        best = cost.argmin(1)
        plan = actions[rows, best]  # [W, H, A]
        if reference is not None and getattr(c, "min_saving", 0.0) > 0:  # candidate 1 is the reference
            keep = cost[rows, 1] - cost[rows, best] < c.min_saving * np.abs(cost[rows, 1])
            plan = np.where(keep[:, None, None], reference, plan)
            best = np.where(keep, 1, best)
        if reference is not None and getattr(c, "consensus", False):  # the own plan, unless every member prefers
            pair = np.stack([plan, reference], axis=1)  # [W, 2, H, A]
            per = self._cost(s, a_last, pair, exo, applies, bounds, comfort_weight, energy_weights, reference,
                             demand, members=True)  # [E, W, 2]  # fmt: skip
            keep = ~np.all(per[:, :, 0] < per[:, :, 1], axis=0)
            plan = np.where(keep[:, None, None], reference, plan)
            best = np.where(keep, 1, best)  # its cost and spread reported: candidate 1 is the reference's
        own_action = own_next = None
        if reference is not None and hold is not None:
            own_action = reference[:, 0]
            plan = np.where(np.asarray(hold, bool)[:, None, None], reference, plan)
            best = np.where(hold, 1, best)
            own_next = self._first_step(s, a_last, reference[:, 0], exo[:, 0])
        steps = np.diff(np.concatenate([a_last[:, None], plan], axis=1), axis=1)
        increments = np.concatenate([steps[:, 1:], np.zeros((w, 1, a_n), np.float32)], axis=1)
        ms = 1000 * (time.perf_counter() - t0)
        return Plan(plan[:, 0].astype(np.float32), increments, cost[rows, best], spread[rows, best], ms, own_action,
                    own_next)

    def _first_step(self, s: np.ndarray, a_last: np.ndarray, action: np.ndarray, exo: np.ndarray) -> np.ndarray:
        """[W, K]: the members' mean zone temperatures at the end of one step of `action` [W, A] from `s`."""
        row = np.concatenate([s, a_last, action, exo], axis=1).astype(np.float32)
        out = self.forward(np.broadcast_to(row, (self.members, *row.shape)).copy())
        return s[:, : self.n_temps] + out[:, :, : self.n_temps].mean(0)

    def _cost(self, s, a_last, actions, exo, applies, bounds, comfort_weight: float,
              energy_weights: np.ndarray | None, reference=None, demand=None, members: bool = False):  # fmt: skip
        """Each candidate's cost over the horizon and its members' largest temperature spread: ([W, N], [W, N]),
        from actions [W, N, H, A]. (Sums, not means, over the members: numpy's mean costs more per call.) A
        `reference` [W, H, A] rides along as one more candidate, each member's discomfort on it subtracted from
        that member's on every candidate. With `demand`, each demand charge pays its price times the rise of the
        members' mean predicted facility demand above the month's running peak, at its highest in the charge's
        window over the horizon. `members`: each member's cost instead, [E, W, N] (the spread and demand terms, which
        are the members' together, added to each)."""
        if reference is not None:
            actions = np.concatenate([actions, reference[:, None]], axis=1)
        w, n, h, a_n = actions.shape
        e, k, ns, b = self.members, self.n_temps, s.shape[1], w * n
        x0, x1 = ns + 2 * a_n, ns + 2 * a_n + exo.shape[2]
        inputs = np.empty((e, w, n, x1), np.float32)  # one row layout: dataset.py's
        inputs[..., :ns] = s[None, :, None]
        inputs[..., ns : ns + a_n] = a_last[None, :, None]
        flat = inputs.reshape(e, b, x1)
        lo = np.repeat(bounds[..., 0] + self.margin, n, axis=0)  # [W*N, H, K]
        hi = np.repeat(bounds[..., 1] - self.margin, n, axis=0)
        applied = np.repeat(applies, n, axis=0) * (comfort_weight / self.margin / k)  # [W*N, H]
        total, worst = np.zeros(b, np.float32), np.zeros(b, np.float32)
        worst_case = self.settings.comfort_risk == "worst"
        weights = None if energy_weights is None else np.repeat(np.asarray(energy_weights, np.float32), n, axis=0)
        energy_scale, spread_scale = self.power_weight / e, self.settings.disagreement_weight
        per = np.zeros((e, b), np.float32) if members else None
        if demand is not None:  # [W*N, H, C]; the rise above the running peak so far, kW [W*N, C]
            d_prices, d_running = (np.repeat(np.asarray(v, np.float32), n, axis=0) for v in (demand.prices,
                                                                                             demand.running))
            rise = np.zeros((b, d_prices.shape[2]), np.float32)
        for step in range(h):
            inputs[..., ns + a_n : x0] = actions[:, :, step]
            inputs[..., x0:] = exo[None, :, None, step]
            out = self.forward(flat)  # [E, W*N, ns]
            temps = flat[:, :, :k] + out[:, :, :k]
            if weights is None:
                total += out[:, :, k:].sum(axis=(0, 2)) * energy_scale
            else:  # [W*N, P] this step's weights
                total += (out[:, :, k:].sum(0) * weights[:, step]).sum(-1) * energy_scale
            if per is not None:
                parts = out[:, :, k:] if weights is None else out[:, :, k:] * weights[None, :, step]
                per += parts.sum(-1) * self.power_weight
            if demand is not None:
                kw = out[:, :, k + demand.part].sum(0) * (1 / e / 1000)  # [W*N]
                above = np.where(d_prices[:, step] > 0, kw[:, None] - d_running[:, step], 0.0)
                np.maximum(rise, above, out=rise)
            over = np.maximum(lo[:, step] - temps, temps - hi[:, step])
            np.maximum(over, 0, out=over)
            if reference is not None:  # beyond the reference's, per member and zone (no credit for beating it)
                rows = over.reshape(e, w, n, k)
                over = np.maximum(rows - rows[:, :, -1:], 0).reshape(e, b, k)
            over = over.sum(-1)  # [E, W*N]
            weight = applied[:, step] * (1 + self.settings.terminal_weight if step == h - 1 else 1)
            if per is not None:
                per += over * weight
            total += (over.max(0) if worst_case else over.sum(0) * (1 / e)) * weight
            if e > 1:
                centred = temps - temps.sum(0) * (1 / e)
                sd = np.sqrt((centred * centred).sum(0) * (1 / (e - 1)))  # [W*N, K]
                total += sd.sum(-1) * spread_scale
                if per is not None:
                    per += sd.sum(-1) * spread_scale
                np.maximum(worst, sd.max(-1), out=worst)
            if step + 1 < h:  # the next step's state and last action
                flat[:, :, :k] = temps
                flat[:, :, k:ns] = out[:, :, k:]
                inputs[..., ns : ns + a_n] = actions[:, :, step]
        if demand is not None:
            total += (rise * d_prices.max(axis=1)).sum(-1) * (demand.per_dollar * self.power_weight)
            if per is not None:
                per += (rise * d_prices.max(axis=1)).sum(-1) * (demand.per_dollar * self.power_weight)
        if per is not None:
            return per.reshape(e, w, n)[:, :, :-1] if reference is not None else per.reshape(e, w, n)
        if reference is not None:
            return total.reshape(w, n)[:, :-1], worst.reshape(w, n)[:, :-1]
        return total.reshape(w, n), worst.reshape(w, n)
