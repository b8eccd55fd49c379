"""The model's data: transitions (state, last action, action, exogenous inputs) -> next state, from every source.

The state is what the model predicts: the spec's comfort temperatures and energy terms (the reward's signals), in
physical units. Where the spec's KPIs name the HVAC signals among the sensors (`[kpis] hvac`), the energy is
predicted in parts: those signals, and the rest of the energy terms' sum (a data center's IT load, an office's
lights and plugs), each with its own physics (the IT power falls as its inlet air gets colder, the fans' power
with their flow); summed, they are the spec's energy again. A row pairs the state after step k with the action
applied during step k+1 (normalized to [-1, 1], as the policy's), the action before it, the exogenous inputs at
the end of step k+1 (exogenous.py) and the state then. Each row keeps its origin (the building's own controls,
exploration, the planner), its episode and step, and whether the comfort band applied, so held-out days and
H-step sequences can be drawn.
"""

from __future__ import annotations

import datetime as dt
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from parallel_eplus.buildings.building import Building, load_building

ORIGINS = ("baseline", "explore", "planner")
_FIELDS = ("s", "a_prev", "a", "x", "s_next", "applies", "episode", "step", "origin")


@dataclass(frozen=True)
class Layout:
    """Where the state's elements sit in a building's observation, and the sizes the model needs."""

    sensors: tuple[str, ...]  # the observed sensors' names, in the observation's order
    temperatures: tuple[str, ...]
    energy: tuple[str, ...]
    n_actions: int
    n_exogenous: int
    hvac: tuple[str, ...] = ()  # the energy's observed HVAC parts; the rest of `energy`'s sum is one more part

    @classmethod
    def of(cls, building: Building, n_exogenous: int) -> Layout:
        energy = tuple(e for e in building.comfort.energy if e not in building.temperatures)
        kpis = building.comfort.kpis
        hvac = tuple(c for _, c in kpis.hvac) if kpis is not None else ()
        observed = tuple(o.name for o in building.observed)
        if not all(c in observed and c not in energy for c in hvac):
            hvac = ()  # an HVAC meter the agent does not observe (the office's gas), or HVAC a term itself: no parts
        return cls(observed, building.temperatures, energy, len(building.actions), n_exogenous, hvac)

    @property
    def state_names(self) -> tuple[str, ...]:
        return self.temperatures + (("non_hvac_w", *self.hvac) if self.hvac else self.energy)

    @property
    def n_state(self) -> int:
        return len(self.state_names)

    @property
    def n_inputs(self) -> int:
        return self.n_state + 2 * self.n_actions + self.n_exogenous

    def state(self, obs: np.ndarray) -> np.ndarray:
        """The state from observations (the sensors come first in the observation), [..., n_state]."""
        obs = np.asarray(obs, np.float32)
        if not self.hvac:
            return obs[..., [self.sensors.index(n) for n in self.state_names]]
        temps = obs[..., [self.sensors.index(n) for n in self.temperatures]]
        hvac = obs[..., [self.sensors.index(n) for n in self.hvac]]
        total = obs[..., [self.sensors.index(n) for n in self.energy]].sum(-1, keepdims=True)
        return np.concatenate([temps, total - hvac.sum(-1, keepdims=True), hvac], axis=-1)


@dataclass
class Transitions:
    """Rows of (s, a_prev, a, x, s_next, applies, episode, step, origin), appended as they come."""

    layout: Layout
    columns: dict[str, list[np.ndarray]] = field(default_factory=dict)

    def add(self, **arrays: np.ndarray) -> None:
        n = len(arrays["s"])
        for name in _FIELDS:
            value = np.asarray(arrays[name])
            if value.shape[:1] != (n,):
                value = np.broadcast_to(value, (n, *value.shape[1:]))
            self.columns.setdefault(name, []).append(value.copy())

    def array(self, name: str) -> np.ndarray:
        parts = self.columns.get(name, [])
        if len(parts) > 1:  # keep one block: appends stay cheap, reads after the first are free
            self.columns[name] = parts = [np.concatenate(parts)]
        return parts[0] if parts else np.zeros(0)

    def __len__(self) -> int:
        return len(self.array("s"))

    def inputs(self, rows=slice(None)) -> tuple[np.ndarray, np.ndarray]:
        """(model inputs, targets): targets are each temperature's change and each energy term's next value."""
        s, s_next = self.array("s")[rows], self.array("s_next")[rows]
        x = np.concatenate([s, self.array("a_prev")[rows], self.array("a")[rows], self.array("x")[rows]], axis=1)
        return x.astype(np.float32), targets(self.layout, s, s_next)

    def held_out(self, block_steps: int, every: int = 5) -> np.ndarray:
        """Rows in held-out blocks (a block is `block_steps` consecutive steps of an episode, e.g. a day): one
        block in `every`, offset by episode, so every weather and season has some."""
        block = self.array("step") // block_steps + self.array("episode")
        return block % every == every - 1

    def sequences(self, rows: np.ndarray, horizon: int) -> np.ndarray:
        """[K, horizon] row indices: runs of `horizon` consecutive steps of one episode, every row in `rows` (a mask).
        Rows of one episode need not be adjacent: workers' steps interleave as they arrive."""
        ep, step = self.array("episode"), self.array("step")
        order = np.lexsort((step, ep))
        ep, step, inside = ep[order], step[order], rows[order]
        n = len(order)
        ok = inside.copy()
        for h in range(1, horizon):
            nxt = np.zeros(n, bool)
            nxt[: n - h] = (ep[h:] == ep[: n - h]) & (step[h:] == step[: n - h] + h) & inside[h:]
            ok &= nxt
        starts = np.flatnonzero(ok)
        return order[starts[:, None] + np.arange(horizon)[None, :]] if len(starts) else np.zeros((0, horizon), int)

    def save(self, path: Path) -> None:
        np.savez_compressed(path, **{name: self.array(name) for name in _FIELDS})

    @classmethod
    def load(cls, path: Path, layout: Layout) -> Transitions:
        with np.load(path) as z:
            data = cls(layout)
            if len(z["s"]):
                data.add(**{name: z[name] for name in _FIELDS})
            return data


def targets(layout: Layout, s: np.ndarray, s_next: np.ndarray) -> np.ndarray:
    k = len(layout.temperatures)
    return np.concatenate([s_next[:, :k] - s[:, :k], s_next[:, k:]], axis=1).astype(np.float32)


def next_state(layout: Layout, s, out):
    """The state after a step from the model's output (`targets`' inverse); numpy or torch."""
    k = len(layout.temperatures)
    if isinstance(s, np.ndarray):
        return np.concatenate([s[..., :k] + out[..., :k], out[..., k:]], axis=-1)
    import torch as th

    return th.cat([s[..., :k] + out[..., :k], out[..., k:]], dim=-1)


class ComfortTimes:
    """When the band applies at a future time, and each zone's bounds then.

    When: always (data centers), by the clock (`hours`), or (a schedule or an observation) as it applied at that
    weekday and time of day in the data so far, counted by majority. With each zone's own thermostat bounds
    (`band = "thermostat"`, the office) at every step: BOPTEST's discomfort counts every step against the occupied
    and the setback bounds. The bounds: the spec's band per zone, or the thermostat's schedules as they were at
    that date and time in the data (every episode runs the model's calendar year, and the building's own controls
    are recorded over it), else at that weekday and time of day (the mean of what was seen; the spec's band where
    nothing was). The date first: a model's schedules follow its holidays and daylight-saving time, which moves an
    office's day an hour earlier from March to November against the simulation's standard-time clock; by weekday
    and time alone, the hours at either end of its day were a blend of both, and the planner let the zones go an
    hour early (2026-11-27)."""

    def __init__(self, building: str | None, step_minutes: float):
        self.comfort = load_building(building).comfort
        self.day_slots = int(round(24 * 60 / step_minutes))
        self.slots = self.day_slots * 7
        self.step_minutes = step_minutes
        self.seen = np.zeros(self.slots)
        self.applied = np.zeros(self.slots)
        self.fixed = np.array(self.comfort.zone_bands, np.float32)  # [K, 2]
        self.bound_sum = np.zeros((self.slots, *self.fixed.shape))
        self.bound_seen = np.zeros(self.slots)
        # per date and time of the year (thermostat bounds only): the last bounds seen there, and the weekday
        # they were seen on (-1: none), so that a period run on another weekday falls back to the weekly slots
        dated = 366 * self.day_slots if self.comfort.per_step else 0
        self.dated = np.zeros((dated, *self.fixed.shape), np.float32)
        self.dated_weekday = np.full(dated, -1, np.int8)

    def _slot(self, t: dt.datetime) -> int:
        return int((t.weekday() * 24 * 60 + t.hour * 60 + t.minute) // self.step_minutes) % self.slots

    def _date_slot(self, t: dt.datetime) -> int:
        minute = (t.timetuple().tm_yday - 1) * 24 * 60 + t.hour * 60 + t.minute
        return int(minute // self.step_minutes) % len(self.dated)

    def learn(self, times: list[dt.datetime], applies: np.ndarray, bounds: np.ndarray | None = None) -> None:
        """`bounds` [T, K, 2]: each zone's bounds at those times (per-step thermostat bounds), else None."""
        for i, (t, a) in enumerate(zip(times, applies, strict=True)):
            k = self._slot(t)
            self.seen[k] += 1
            self.applied[k] += bool(a)
            if bounds is not None and self.comfort.per_step:
                self.bound_sum[k] += bounds[i]
                self.bound_seen[k] += 1
                d = self._date_slot(t)
                self.dated[d], self.dated_weekday[d] = bounds[i], t.weekday()

    def __call__(self, times: list[dt.datetime]) -> np.ndarray:
        c = self.comfort
        if c.always or c.per_step:
            return np.ones(len(times), np.float32)
        if c.occupied.observation is None:
            return np.array([c.applies(t, {}) for t in times], np.float32)
        slots = [self._slot(t) for t in times]
        return np.array([self.applied[k] * 2 > self.seen[k] for k in slots], np.float32)

    def bounds(self, times: list[dt.datetime]) -> np.ndarray:
        """Each zone's (lower, upper) edges at `times`, [T, K, 2]: its bounds widened by the spec's `tolerance`, the
        edges the share in band counts (comfort.py `cost`)."""
        widen = np.array([-self.comfort.tolerance, self.comfort.tolerance], np.float32)
        if not self.comfort.per_step:
            return np.broadcast_to(self.fixed + widen, (len(times), *self.fixed.shape))
        slots = [self._slot(t) for t in times]
        seen = self.bound_seen[slots][:, None, None]
        mean = np.where(seen > 0, self.bound_sum[slots] / np.maximum(seen, 1), self.fixed)
        dates = [self._date_slot(t) for t in times]
        known = (self.dated_weekday[dates] == [t.weekday() for t in times])[:, None, None]
        return (np.where(known, self.dated[dates], mean) + widen).astype(np.float32)

    def state(self) -> dict[str, np.ndarray]:
        """The weekly slots' counts and sums; the dated bounds as runs (each entry holds until the next: a
        schedule changes a few times a day, so a year is a few thousand entries, not 52,560)."""
        out = {"comfort_seen": self.seen, "comfort_applied": self.applied, "bound_sum": self.bound_sum,
               "bound_seen": self.bound_seen}  # fmt: skip
        if len(self.dated):
            flat, day = self.dated.reshape(len(self.dated), -1), self.dated_weekday
            starts = np.ones(len(day), bool)
            starts[1:] = (day[1:] != day[:-1]) | np.any(flat[1:] != flat[:-1], axis=1)
            at = np.flatnonzero(starts)
            out |= {"dated_runs": at.astype(np.int32), "dated_bounds": self.dated[at], "dated_weekday": day[at]}
        return out

    def load(self, state: dict) -> None:
        """From `state()`'s arrays (a planner saved before the bounds were learned has none: the spec's band)."""
        self.seen = np.asarray(state["comfort_seen"], float)
        self.applied = np.asarray(state["comfort_applied"], float)
        if "bound_sum" in state:
            self.bound_sum = np.asarray(state["bound_sum"], float)
            self.bound_seen = np.asarray(state["bound_seen"], float)
        if not len(self.dated) or "dated_bounds" not in state:
            return
        bounds, day = np.asarray(state["dated_bounds"], np.float32), np.asarray(state["dated_weekday"], np.int8)
        if "dated_runs" in state:  # each run holds until the next one starts
            run = np.searchsorted(np.asarray(state["dated_runs"], int), np.arange(len(self.dated)), side="right") - 1
            self.dated, self.dated_weekday = bounds[run], day[run]
        else:  # the first planners (2026-11-27): the entries that differ from the weekly slots' means
            at = np.asarray(state["dated_at"], int)
            self.dated[at], self.dated_weekday[at] = bounds, day

    def bounds_of(self, values: dict) -> np.ndarray | None:
        """[1, K, 2]: a step's per-zone thermostat bounds from its sensor values (info), or None."""
        if not self.comfort.per_step:
            return None
        return np.array([self.comfort.bounds(values)], float)
