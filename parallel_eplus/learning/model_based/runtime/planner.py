"""The planner: the cross-entropy method (CEM) over bounded increments of the last action, on the ensemble.

For every worker at once: `candidates` sequences of `horizon` increments (each within ±`max_increment` of the
normalized action, the action itself within the data's support) are rolled out through every member of the
ensemble, the whole horizon in one call (ensemble_graph.py `build_rollout`), scored, and the best `elites` refit
the sampling distribution, `iterations` times; the best sequence's first action is applied and the rest
(`Plan.increments`) warm-starts the next step's search.

The cost of a step (`Planner._add_step_cost`, the one place it is written; students/through_model.py has it in
torch for the gradient, term for term) is the spec's energy term (every fuel, times the reward's `power_weight`:
about 1 per step; under another objective each predicted part weighed as the reward weighs it at that step,
energy_weights.py), plus `comfort_weight` times the comfort surrogate of the constraint (learning/lagrangian.py: 0
inside each zone's bounds shrunk by the margin, rising by 1 per margin beyond, here unbounded so the search is
pushed back in), where the band applies (the bounds: the spec's band, or each zone's thermostat schedules, calendar.py),
plus `disagreement_weight` times the members' spread of each zone temperature (K): the planner stays where the
model knows the building. Each member follows its own trajectory (PETS's "TS-inf"); the comfort term is the
members' mean, or with `comfort_risk = "worst"` the worst member's (a chance constraint: the band held by every
member's prediction, not by their average); `terminal_weight` weighs the horizon's last step's comfort more (a
plan must not end at the band's edge, where the next plan has no room). Measured against the baseline, the building's
own controls' plan (`reference`), `baseline_radius` keeps its thermostats near it and `min_saving` plays it unless the
search's plan
is predicted to save that share: the model knows the building only near what it has seen, and the best of hundreds
of candidates is the one its errors favour most.

A plan is a function of the planner's settings (`PlannerSettings`: the in-process planner's from its MPCSettings, the
served one's from its contract) and of what one decision sees (`PlanRequest`). Numpy and onnxruntime only: the
sampler is seeded per decision from what the decision sees (`decision_seed`), so a served planner answers a request
exactly as the in-process one acts.
"""

from __future__ import annotations

import functools
import hashlib
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import asdict, dataclass, field, fields, replace
from typing import TYPE_CHECKING

import numpy as np

from parallel_eplus.learning.model_based.runtime.renamed import renamed_settings

if TYPE_CHECKING:
    from parallel_eplus.learning.model_based.runtime.demand import DemandOutlook

Forward = Callable[[np.ndarray], np.ndarray]  # [members, batch, inputs] -> [members, batch, targets], physical


@dataclass(frozen=True, kw_only=True)
class PlannerSettings:
    """What a plan reads of `--mpc`, and what the served planner reads beside it (`occupancy_input`, `guard_k`,
    `guard_steps`, `baseline_margin`): the fields an export writes into its contract. MPCSettings
    (learning/model_based/settings.py) says what each means. One type for both planners: the in-process one takes
    them from its MPCSettings, the served one from its contract, where the training stack is not installed; a field
    a contract written before it lacks takes MPCSettings' default (tests/test_planner_request.py checks they agree)."""

    horizon: int
    candidates: int
    iterations: int
    elites: int
    shrink: float = 1.0
    max_increment: float
    init_std: float
    disagreement_weight: float
    comfort_risk: str = "mean"
    terminal_weight: float = 0.0
    consensus: bool = False
    min_saving: float = 0.0
    baseline_radius: float | None = None
    occupancy_input: bool = False
    guard_k: float | None = None
    guard_steps: int = 12
    band_thermostats: str = "free"
    band_lead: int = 0
    baseline_margin: float = 0.0

    @classmethod
    def of(cls, settings) -> PlannerSettings:
        """These fields of an MPCSettings, or of a contract's `settings` (a mapping; other keys ignored; names and
        values from before 1.1 renamed, renamed.py)."""
        values = renamed_settings(settings, "a contract") if isinstance(settings, Mapping) else asdict(settings)
        return cls(**{f.name: values[f.name] for f in fields(cls) if f.name in values})


def _shaped(dims: str, **kwargs):
    """A `PlanRequest` field of the shape `dims` (axis names, or sizes; checked when a request is made)."""
    return field(metadata={"shape": tuple(int(d) if d.isdigit() else d for d in dims.split())}, **kwargs)


@dataclass(frozen=True)
class PlanRequest:
    """What one decision sees, for W workers at once (the served planner: one). Shapes name their axes: W workers,
    H the horizon's steps, A actions, S the model's state, X its exogenous inputs, K zones, P energy parts, C demand
    charges; actions are normalized ([-1, 1]). A field of the wrong shape, or whose sizes disagree with another's, is
    a ValueError naming it (`Planner.plan` also refuses a horizon that is not its settings')."""

    state: np.ndarray = _shaped("W S")  # the model's state: zone temperatures, then energy parts (Layout.state)
    last_action: np.ndarray = _shaped("W A")  # the action of the step that just ended
    exogenous: np.ndarray = _shaped("W H X")  # the model's exogenous inputs at each coming step's end
    applies: np.ndarray = _shaped("W H")  # where the comfort band applies (> 0) at each coming step's end
    # each zone's comfort bounds (low, high), degC, at each coming step's end: the spec's band, or each zone's
    # thermostat schedules (calendar.py)
    bounds: np.ndarray = _shaped("W H K 2")
    comfort_weight: float  # the comfort surrogate's weight: the run's Lagrange multiplier, or a fixed one
    support: tuple[np.ndarray, np.ndarray]  # (low [A], high [A]): the actions' range in the model's data
    warm: np.ndarray = _shaped("W H A")  # the increments the search starts from: the last `Plan.increments`, or 0
    seeds: Sequence[int]  # one sampler seed per worker (`decision_seed`)
    # the weights of the predicted energy parts at each step, as the run's objective prices them (energy_weights.py);
    # None: each counts once
    energy_weights: np.ndarray | None = _shaped("W H P", default=None)
    # the actions whose predicted discomfort is free (`comfort_reference = "baseline"`: the baseline, calendar.py
    # `own_reference`); itself a candidate, so the search can always fall back on it. None: every K beyond the
    # bounds costs
    reference: np.ndarray | None = _shaped("W H A", default=None)
    demand: DemandOutlook | None = None  # the demand charges over the horizon (demand.py); None: none priced
    # the actions the reference sets, kept near it (baseline_radius)
    follows: np.ndarray | None = _shaped("A", default=None)
    hold: np.ndarray | None = _shaped("W", default=None)  # the workers that play the reference (guard.py)
    # which bound each action's own setpoint is (0 the lower: heating, 1 the upper: cooling, -1 not a thermostat;
    # `side_array`), which `band_thermostats` holds to the reference where the band applies
    sides: np.ndarray | None = _shaped("A", default=None)

    def __post_init__(self):
        put = functools.partial(object.__setattr__, self)
        put("state", np.asarray(self.state, np.float32))
        put("last_action", np.asarray(self.last_action, np.float32))
        put("exogenous", np.asarray(self.exogenous))
        put("applies", np.asarray(self.applies))
        put("bounds", np.asarray(self.bounds))
        put("support", tuple(np.asarray(b, np.float32) for b in self.support))
        put("warm", np.asarray(self.warm, np.float32))
        put("seeds", tuple(self.seeds))
        if self.energy_weights is not None:
            put("energy_weights", np.asarray(self.energy_weights))
        if self.reference is not None:
            put("reference", np.asarray(self.reference, np.float32))
        if self.follows is not None:
            put("follows", np.asarray(self.follows, bool))
        if self.hold is not None:
            put("hold", np.asarray(self.hold, bool))
        if self.sides is not None:
            put("sides", np.asarray(self.sides))
        sizes: dict[str, int] = {}
        for f in fields(self):
            value = getattr(self, f.name)
            if "shape" in f.metadata and value is not None:
                _check_shape(f.name, value.shape, f.metadata["shape"], sizes)
        if len(self.support) != 2:
            raise ValueError(f"PlanRequest.support: (low, high), got {len(self.support)} arrays")
        for name, bound in zip(("support[0]", "support[1]"), self.support, strict=True):
            _check_shape(name, bound.shape, ("A",), sizes)
        if len(self.seeds) != sizes["W"]:
            raise ValueError(f"PlanRequest.seeds: {len(self.seeds)} seeds, expected one per worker (W={sizes['W']})")
        if self.demand is not None:
            for name, value in (("demand.prices", self.demand.prices), ("demand.running", self.demand.running)):
                _check_shape(name, np.shape(value), ("W", "H", "C"), sizes)

    @property
    def horizon(self) -> int:
        """H: the steps the request looks ahead."""
        return self.warm.shape[1]


def _check_shape(name: str, shape: tuple[int, ...], dims: tuple[str | int, ...], sizes: dict[str, int]) -> None:
    """`shape` against `dims` (axis names, or sizes): a name's size is the one it first had (kept in `sizes`)."""
    if len(shape) == len(dims) and all((sizes.setdefault(d, n) if isinstance(d, str) else d) == n
                                       for d, n in zip(dims, shape, strict=True)):  # fmt: skip
        return
    expected = ", ".join(f"{d}={sizes[d]}" if d in sizes else str(d) for d in dims)
    raise ValueError(f"PlanRequest.{name}: shape {tuple(shape)}, expected [{expected}]")


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
    """CEM over action increments, on `forward`'s ensemble of `members` (its state's first `n_temps` the zone
    temperatures); `margin_c` and `power_weight`: the run's comfort margin and the reward's weight of energy."""

    def __init__(self, forward: Forward, members: int, n_temps: int, settings: PlannerSettings, margin_c: float,
                 power_weight: float):  # fmt: skip
        self.forward, self.members, self.n_temps, self.settings = forward, members, n_temps, settings
        self.margin, self.power_weight = margin_c, power_weight

    def plan(self, request: PlanRequest) -> Plan:
        """One decision for every worker of `request`, with `self.settings`. The reference is searched as a
        candidate can follow it (within the support, `max_increment` a step) and scored so (`_cost`)."""
        t0 = time.perf_counter()
        c, r = self.settings, request
        if r.horizon != c.horizon:
            raise ValueError(f"PlanRequest: {r.horizon} steps ahead, the planner's horizon is {c.horizon}")
        s, a_last, (low, high) = r.state, r.last_action, r.support
        w, h, a_n = len(s), c.horizon, a_last.shape[1]
        reference = None
        if r.reference is not None:  # as a candidate can follow it: within the support, ±max_increment a step
            reference = _follow(a_last, r.reference, c.max_increment, low, high)
            r = replace(r, reference=reference)
        near = None
        if reference is not None and c.baseline_radius is not None and r.follows is not None:  # [W, 1, H, A] each
            radius = np.where(r.follows, np.float32(c.baseline_radius), np.float32(np.inf))
            near = (reference[:, None] - radius, reference[:, None] + radius)
        if reference is not None and c.band_thermostats != "free" and r.sides is not None:
            inside = _ahead(r.applies > 0, c.band_lead)[:, None, :, None]  # [W, 1, H, 1]
            sides, exact = r.sides, c.band_thermostats == "baseline"
            low_ = np.where(inside & ((sides == 0) | exact & (sides >= 0)), reference[:, None], -np.inf)  # heating
            high_ = np.where(inside & ((sides == 1) | exact & (sides >= 0)), reference[:, None], np.inf)  # cooling
            near = (low_, high_) if near is None else (np.maximum(near[0], low_), np.minimum(near[1], high_))
        rngs = [np.random.default_rng(seed) for seed in r.seeds]
        mean, std = r.warm.copy(), np.full((w, h, a_n), c.init_std, np.float32)
        for i in range(c.iterations):
            # each iteration searches a narrower distribution: `shrink` of the last one's candidates and elites
            n = max(int(round(c.candidates * c.shrink**i)), 2)
            elites = max(int(round(c.elites * c.shrink**i)), 2)
            noise = np.stack([rng.standard_normal((n, h, a_n), np.float32) for rng in rngs])
            delta = mean[:, None] + std[:, None] * noise
            delta[:, 0] = mean  # the warm start itself is always a candidate
            if reference is not None:  # and so is the reference: the own thermostats' plan, as far as it can be
                delta[:, 1] = np.diff(np.concatenate([a_last[:, None], reference], axis=1), axis=1)
            np.clip(delta, -c.max_increment, c.max_increment, out=delta)
            actions = np.clip(a_last[:, None, None, :] + np.cumsum(delta, axis=2), low, high)
            if near is not None:
                np.clip(actions, *near, out=actions)
            cost, spread = self._cost(r, actions)
            elite = np.argpartition(cost, elites - 1, axis=1)[:, :elites]
            chosen = np.take_along_axis(delta, elite[:, :, None, None], axis=1)
            mean, std = chosen.mean(1), np.maximum(chosen.std(1, ddof=1), 0.01)
        rows = np.arange(w)
        best = cost.argmin(1)
        plan = actions[rows, best]  # [W, H, A]
        if reference is not None and c.min_saving > 0:  # candidate 1 is the reference
            keep = cost[rows, 1] - cost[rows, best] < c.min_saving * np.abs(cost[rows, 1])
            plan = np.where(keep[:, None, None], reference, plan)
            best = np.where(keep, 1, best)
        if reference is not None and c.consensus:  # the own plan, unless every member prefers
            per = self._cost(r, np.stack([plan, reference], axis=1), members=True)  # [E, W, 2]
            keep = ~np.all(per[:, :, 0] < per[:, :, 1], axis=0)
            plan = np.where(keep[:, None, None], reference, plan)
            best = np.where(keep, 1, best)  # its cost and spread reported: candidate 1 is the reference's
        own_action = own_next = None
        if reference is not None and r.hold is not None:
            own_action = reference[:, 0]
            plan = np.where(r.hold[:, None, None], reference, plan)
            best = np.where(r.hold, 1, best)
            own_next = self._first_step(s, a_last, reference[:, 0], r.exogenous[:, 0])
        steps = np.diff(np.concatenate([a_last[:, None], plan], axis=1), axis=1)
        increments = np.concatenate([steps[:, 1:], np.zeros((w, 1, a_n), np.float32)], axis=1)
        ms = 1000 * (time.perf_counter() - t0)
        return Plan(
            plan[:, 0].astype(np.float32), increments, cost[rows, best], spread[rows, best], ms, own_action, own_next
        )

    def _first_step(self, s: np.ndarray, a_last: np.ndarray, action: np.ndarray, exo: np.ndarray) -> np.ndarray:
        """[W, K]: the members' mean zone temperatures at the end of one step of `action` [W, A] from `s`."""
        row = np.concatenate([s, a_last, action, exo], axis=1).astype(np.float32)
        out = self.forward(np.broadcast_to(row, (self.members, *row.shape)).copy())
        return s[:, : self.n_temps] + out[:, :, : self.n_temps].mean(0)

    def _cost(self, request: PlanRequest, actions: np.ndarray, members: bool = False):
        """Each candidate's cost over the horizon and its members' largest temperature spread: ([W, N], [W, N]),
        from actions [W, N, H, A]. The request's `reference` [W, H, A] (as given: `plan` gives it as a candidate
        can follow it) rides along as one more candidate, each member's discomfort on it subtracted from that
        member's on every candidate. With `demand`, each demand charge pays its price times the rise of the members'
        mean predicted facility demand above the month's running peak, at its highest in the charge's window over
        the horizon. `members`: each member's cost instead, [E, W, N] (the spread and demand terms, which are the
        members' together, added to each)."""
        r = request
        s, a_last, exo, reference, demand = r.state, r.last_action, r.exogenous, r.reference, r.demand
        if reference is not None:
            actions = np.concatenate([actions, reference[:, None]], axis=1)
        w, n, h, a_n = actions.shape
        e, k, b = self.members, self.n_temps, w * n
        states = self._rollout(s, a_last, actions, exo)  # [H, E, S, W*N]
        # each step's bounds, where the band applies and the energy weights, the candidates last: [H, ..., W*N]
        lo = np.repeat((r.bounds[..., 0] + self.margin).transpose(1, 2, 0), n, axis=-1)  # [H, K, W*N]
        hi = np.repeat((r.bounds[..., 1] - self.margin).transpose(1, 2, 0), n, axis=-1)
        applied = np.repeat(r.applies.T, n, axis=-1) * (r.comfort_weight / self.margin / k)  # [H, W*N]
        weights = None
        if r.energy_weights is not None:  # [H, P, W*N]
            weights = np.repeat(np.asarray(r.energy_weights, np.float32).transpose(1, 2, 0), n, axis=-1)
        terms = self._step_terms(states[:, :, k:], states[:, :, :k], lo, hi, applied, self._terminal(h),
                                 weights=weights, reference_every=None if reference is None else n,
                                 members=members)  # fmt: skip
        cost = np.zeros((e, b) if members else b, np.float32)
        for step in range(h):  # in the order a step at a time adds them (`_add_step_cost`)
            for term in terms[:3]:
                if term is not None:
                    cost += term[step]
        worst = np.zeros(b, np.float32) if terms[3] is None else terms[3].max(-2).max(0)
        if demand is not None:  # [W*N, H, C]; the rise above the running peak so far, kW [W*N, C]
            d_prices, d_running = (
                np.repeat(np.asarray(v, np.float32), n, axis=0) for v in (demand.prices, demand.running)
            )
            kw = states[:, :, k + demand.part].sum(1) * (1 / e / 1000)  # [H, W*N]
            above = np.where(d_prices > 0, kw.T[:, :, None] - d_running, 0.0)  # [W*N, H, C]
            rise = np.maximum(above.max(1), 0)
            cost += (rise * d_prices.max(axis=1)).sum(-1) * (demand.per_dollar * self.power_weight)
        if members:
            return cost.reshape(e, w, n)[:, :, :-1] if reference is not None else cost.reshape(e, w, n)
        if reference is not None:
            return cost.reshape(w, n)[:, :-1], worst.reshape(w, n)[:, :-1]
        return cost.reshape(w, n), worst.reshape(w, n)

    def _terminal(self, h: int) -> np.ndarray:
        """[H, 1]: each step's comfort factor, 1 + `terminal_weight` on the horizon's last."""
        factor = np.ones((h, 1), np.float32)
        factor[-1] = 1 + self.settings.terminal_weight
        return factor

    def _rollout(self, s: np.ndarray, a_last: np.ndarray, actions: np.ndarray, exo: np.ndarray) -> np.ndarray:
        """[H, E, S, W*N]: each member's state after each step of the candidates' `actions` [W, N, H, A] from `s`
        [W, S] (each worker's, the same for its N candidates) after `a_last` [W, A], with `exo` [W, H, X]: the zone
        temperatures plus the predicted changes, then the predicted energy parts. One call of the forward's rollout
        graph (ensemble_graph.py `build_rollout`) where it has one, else a call of the forward per step; the same
        numbers either way."""
        w, n, h, a_n = actions.shape
        e, k, ns, b = self.members, self.n_temps, s.shape[1], w * n
        rollout = getattr(self.forward, "rollout", None)
        rollout = rollout and rollout(h, k)
        steps = np.ascontiguousarray(actions.transpose(2, 0, 1, 3)).reshape(h, b, a_n)  # [H, W*N, A]
        exo_rows = np.repeat(np.asarray(exo, np.float32).swapaxes(0, 1), n, axis=1)  # [H, W*N, X]
        if rollout is not None:
            return rollout(np.repeat(s, n, axis=0), np.repeat(a_last, n, axis=0), steps, exo_rows)
        x0, x1 = ns + 2 * a_n, ns + 2 * a_n + exo.shape[2]
        flat = np.empty((e, b, x1), np.float32)  # one row layout: dataset.py's
        flat[..., :ns] = np.repeat(s, n, axis=0)
        flat[..., ns : ns + a_n] = np.repeat(a_last, n, axis=0)
        states = np.empty((h, e, ns, b), np.float32)
        for step in range(h):
            flat[..., ns + a_n : x0] = steps[step]
            flat[..., x0:] = exo_rows[step]
            out = self.forward(flat)  # [E, W*N, ns]
            flat[..., :k] += out[..., :k]  # the next step's state and last action
            flat[..., k:ns] = out[..., k:]
            flat[..., ns : ns + a_n] = steps[step]
            states[step] = flat[..., :ns].swapaxes(1, 2)
        return states

    def _add_step_cost(self, cost: np.ndarray, out: np.ndarray, temps: np.ndarray, lo: np.ndarray, hi: np.ndarray,
                       applied: np.ndarray, *, last: bool, weights: np.ndarray | None,
                       reference_every: int | None) -> np.ndarray | None:  # fmt: skip
        """One step's cost (`_step_terms`), added to `cost` [B], the members' together, or [E, B], each member's,
        from the members' predictions `out` [E, B, targets] (the energy parts after the `n_temps` temperature
        changes) and zone temperatures `temps` [E, B, K], the bounds `lo`, `hi` [B, K], `applied` [B] and `weights`
        [B, P]; `last`: the horizon's last step. Returns the spread [B, K] (None with one member)."""
        factor = np.float32(1 + self.settings.terminal_weight if last else 1)
        t = functools.partial(np.swapaxes, axis1=-1, axis2=-2)  # the candidates last, as `_step_terms` reads them
        terms = self._step_terms(t(out[..., self.n_temps :]), t(temps), t(lo), t(hi), applied, factor,
                                 weights=None if weights is None else t(weights), reference_every=reference_every,
                                 members=cost.ndim == 2)  # fmt: skip
        for term in terms[:3]:
            if term is not None:
                cost += term
        return None if terms[3] is None else t(terms[3])

    def _step_terms(self, parts: np.ndarray, temps: np.ndarray, lo: np.ndarray, hi: np.ndarray, applied: np.ndarray,
                    factor: np.ndarray, *, weights: np.ndarray | None, reference_every: int | None,
                    members: bool) -> tuple:  # fmt: skip
        """A step's cost, the one place it is written (the module's docstring says why each term), as its three terms
        (energy, comfort, disagreement: each [..., B], the members' together, or [..., E, B], each member's; the
        last None with one member) and the members' spread [..., K, B] (None with one member). For one step or for
        every step at once (a leading step axis "..." on every array), the candidates last: from the members'
        predicted energy parts `parts` [..., E, P, B] and zone temperatures `temps` [..., E, K, B]:

        - energy: every predicted part, each times its weight this step (`weights` [..., P, B]; None: 1), times
          `power_weight`; the members' mean;
        - comfort: the K beyond each zone's bounds shrunk by the margin (`lo`, `hi` [..., K, B]), summed over zones,
          times `applied` [..., B] (where the band applies, times comfort_weight / margin / K), times `factor` (1, or
          1 + `terminal_weight` on the horizon's last step; [..., 1]); the members' mean, or with `comfort_risk =
          "worst"` the worst member's. With a reference (the last of every `reference_every` candidates), only what
          a member's prediction has beyond its own on the reference;
        - disagreement: the members' spread (standard deviation) of each zone temperature, summed over zones, times
          `disagreement_weight`; the same for each member.

        Sums, not means, over the members: numpy's mean costs more per call; sums over parts and zones in the order
        numpy sums a row (`_row_sum`). students/through_model.py `Rollouts.cost` is this step in torch, term for
        term."""
        e = self.members
        if members:
            energy = _row_sum(parts if weights is None else parts * weights[..., None, :, :]) * self.power_weight
        elif weights is None:
            energy = _row_sum(parts).sum(-2) * (self.power_weight / e)
        else:
            energy = _row_sum(parts.sum(-3) * weights) * (self.power_weight / e)
        over = lo[..., None, :, :] - temps  # in place from here: fewer arrays made per call
        np.maximum(over, temps - hi[..., None, :, :], out=over)
        np.maximum(over, 0, out=over)
        if reference_every is not None:  # beyond the reference's, per member and zone (no credit for beating it)
            rows = over.reshape(*over.shape[:-1], -1, reference_every)
            over = np.maximum(rows - rows[..., -1:], 0).reshape(over.shape)
        over = _row_sum(over)  # [..., E, B]
        weight = applied * factor
        if members:
            comfort = over * weight[..., None, :]
        else:
            comfort = (over.max(-2) if self.settings.comfort_risk == "worst" else over.sum(-2) * (1 / e)) * weight
        if e == 1:
            return energy, comfort, None, None
        centred = temps - temps.sum(-3, keepdims=True) * (1 / e)
        sd = np.multiply(centred, centred, out=centred).sum(-3)
        np.sqrt(np.multiply(sd, 1 / (e - 1), out=sd), out=sd)  # [..., K, B]
        spread = _row_sum(sd) * self.settings.disagreement_weight
        return energy, comfort, spread[..., None, :] if members else spread, sd


def _row_sum(x: np.ndarray) -> np.ndarray:
    """`x` [..., R, B] summed over R, in the order numpy sums a row of R numbers (`sum(-1)` of [..., B, R]): one
    after the other below 8, pairwise from 8 (where it needs the copy)."""
    if x.shape[-2] < 8:
        return x.sum(-2)
    return np.ascontiguousarray(np.swapaxes(x, -1, -2)).sum(-1)
