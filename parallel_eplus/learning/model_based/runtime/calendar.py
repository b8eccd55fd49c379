"""When the band applies at a future time, and each zone's bounds then: learned while training (`ComfortTimes`),
read by the planner in process and, exported as arrays, by the served planner (`Calendar`): one lookup for both.

When: always (data centers), by the clock (the spec's occupied `hours`: a weekly table of slots), or (a schedule
or an observation) as it applied at that weekday and time of day in the data so far, counted by majority. With
each zone's own thermostat bounds (`band = "thermostat"`, the office) at every step: BOPTEST's discomfort counts
every step against the occupied and the setback bounds. The bounds: the spec's band per zone, or the thermostat's
schedules as they were at that date and time in the data (every episode runs the model's calendar year, and the
building's own controls are recorded over it), else at that weekday and time of day (the mean of what was seen;
the spec's band where nothing was). The date first: a model's schedules follow its holidays and daylight-saving
time, which moves an office's day an hour earlier from March to November against the simulation's standard-time
clock; by weekday and time alone, the hours at either end of its day were a blend of both, and the planner let the
zones go an hour early (2026-11-27). With `occupied_only` (the planner's `comfort_hours = "occupied"`) the
thermostat's bounds count only where the band applies (its occupied hours, as recorded on that date, else by
majority at that weekday and time): what the share in own bounds and occupied K.h score. Every step's setback
bound cost the warehouse's planner heat at night that no score counted (docs/model-based.md). By date too, what
the building's own controls set for each action (`learn_own`, from their record): the own plan of an action no
thermostat schedule gives (a supply-air node), for `comfort_reference = "baseline"`.
Numpy only: the server imports this.
"""

from __future__ import annotations

import datetime as dt

import numpy as np

from parallel_eplus.buildings.scaling import normalize

ALWAYS, CLOCK, OBSERVED, THERMOSTAT = "always", "clock", "observed", "thermostat"


class Calendar:
    """The lookups, from arrays: `state()` writes them, `from_state` reads them back (a planner file, an export)."""

    def __init__(self, mode: str, step_minutes: float, fixed: np.ndarray, tolerance: float,
                 clock: np.ndarray | None = None, occupied_only: bool = False):  # fmt: skip
        self.mode, self.step_minutes, self.tolerance = mode, step_minutes, float(tolerance)
        self.occupied_only = occupied_only
        self.day_slots = int(round(24 * 60 / step_minutes))
        self.slots = self.day_slots * 7
        self.fixed = np.asarray(fixed, np.float32)  # [K, 2]: the spec's band per zone
        self.clock = clock  # [slots]: whether the band applies by the clock (mode CLOCK)
        self.seen, self.applied = np.zeros(self.slots), np.zeros(self.slots)
        self.bound_sum, self.bound_seen = np.zeros((self.slots, *self.fixed.shape)), np.zeros(self.slots)
        # per date and time of the year (thermostat bounds only): the last bounds seen there, and the weekday
        # they were seen on (-1: none), so that a period run on another weekday falls back to the weekly slots
        dated = 366 * self.day_slots if mode == THERMOSTAT else 0
        self.dated = np.zeros((dated, *self.fixed.shape), np.float32)
        self.dated_weekday = np.full(dated, -1, np.int8)
        self.dated_applies = np.full(dated, -1, np.int8)  # -1: not recorded (a planner saved before it was kept)
        # [dated, A]: what the building's own controls set (normalized) for the step ending there, NaN: not recorded
        self.dated_own = np.zeros((dated, 0), np.float32)
        self._own_known = np.zeros(0, bool)  # per action: any date recorded (read at every plan: kept, not counted)

    def _slot(self, t: dt.datetime) -> int:
        return int((t.weekday() * 24 * 60 + t.hour * 60 + t.minute) // self.step_minutes) % self.slots

    def _date_slot(self, t: dt.datetime) -> int:
        minute = (t.timetuple().tm_yday - 1) * 24 * 60 + t.hour * 60 + t.minute
        return int(minute // self.step_minutes) % len(self.dated)

    def __call__(self, times: list[dt.datetime]) -> np.ndarray:
        """Whether the band applies to the steps ending at `times`, [T]."""
        if self.mode == THERMOSTAT and not self.occupied_only:
            return np.ones(len(times), np.float32)
        return self.occupied(times)

    def occupied(self, times: list[dt.datetime]) -> np.ndarray:
        """Whether the building is occupied (its band applies) at the steps ending at `times`, [T], whatever
        `occupied_only`: by date where recorded, else by the clock or the weekly majority."""
        if self.mode == ALWAYS:
            return np.ones(len(times), np.float32)
        slots = [self._slot(t) for t in times]
        if self.mode == CLOCK:
            return self.clock[slots].astype(np.float32)
        observed = np.array([self.applied[k] * 2 > self.seen[k] for k in slots], np.float32)
        if not len(self.dated):
            return observed
        dates = [self._date_slot(t) for t in times]
        known = (self.dated_weekday[dates] == [t.weekday() for t in times]) & (self.dated_applies[dates] >= 0)
        return np.where(known, self.dated_applies[dates], observed).astype(np.float32)

    def bounds(self, times: list[dt.datetime]) -> np.ndarray:
        """Each zone's (lower, upper) edges at `times`, [T, K, 2]: its bounds widened by the spec's `tolerance`, the
        edges the share in band counts (comfort.py `cost`)."""
        widen = np.array([-self.tolerance, self.tolerance], np.float32)
        if self.mode != THERMOSTAT:
            return np.broadcast_to(self.fixed + widen, (len(times), *self.fixed.shape))
        slots = [self._slot(t) for t in times]
        seen = self.bound_seen[slots][:, None, None]
        mean = np.where(seen > 0, self.bound_sum[slots] / np.maximum(seen, 1), self.fixed)
        dates = [self._date_slot(t) for t in times]
        known = (self.dated_weekday[dates] == [t.weekday() for t in times])[:, None, None]
        return (np.where(known, self.dated[dates], mean) + widen).astype(np.float32)

    def own_actions(self, times: list[dt.datetime]) -> np.ndarray | None:
        """What the building's own controls set for the steps ending at `times`, [T, A] normalized (NaN where that
        date was not recorded, or fell on another weekday), or None (no record)."""
        if not self.dated_own.shape[1]:
            return None
        dates = [self._date_slot(t) for t in times]
        known = (self.dated_weekday[dates] == [t.weekday() for t in times])[:, None]
        return np.where(known, self.dated_own[dates], np.nan).astype(np.float32)

    def own_known(self, n_actions: int) -> np.ndarray:
        """[A]: the actions whose own controls' setpoints were recorded by date."""
        known = self._own_known
        return known if len(known) == n_actions else np.zeros(n_actions, bool)

    # -- as arrays ------------------------------------------------------------------------------
    def state(self) -> dict[str, np.ndarray]:
        """The weekly slots' counts and sums; the dated bounds as runs (each entry holds until the next: a
        schedule changes a few times a day, so a year is a few thousand entries, not 52,560)."""
        out = {"comfort_seen": self.seen, "comfort_applied": self.applied, "bound_sum": self.bound_sum,
               "bound_seen": self.bound_seen}  # fmt: skip
        if len(self.dated):
            flat, day, on = self.dated.reshape(len(self.dated), -1), self.dated_weekday, self.dated_applies
            starts = np.ones(len(day), bool)
            starts[1:] = (day[1:] != day[:-1]) | (on[1:] != on[:-1]) | np.any(flat[1:] != flat[:-1], axis=1)
            at = np.flatnonzero(starts)
            out |= {"dated_runs": at.astype(np.int32), "dated_bounds": self.dated[at], "dated_weekday": day[at],
                    "dated_applies": on[at]}  # fmt: skip
        if self.dated_own.shape[1]:  # as runs too: a supply-air reset changes a few times a day at most
            own = self.dated_own
            same = (own[1:] == own[:-1]) | (np.isnan(own[1:]) & np.isnan(own[:-1]))
            starts = np.concatenate([[True], ~same.all(axis=1)])
            at = np.flatnonzero(starts)
            out |= {"own_runs": at.astype(np.int32), "own_actions": own[at]}
        return out

    def load(self, state: dict) -> None:
        """From `state()`'s arrays (a planner saved before the bounds were learned has none: the spec's band)."""
        self.seen = np.asarray(state["comfort_seen"], float)
        self.applied = np.asarray(state["comfort_applied"], float)
        if "bound_sum" in state:
            self.bound_sum = np.asarray(state["bound_sum"], float)
            self.bound_seen = np.asarray(state["bound_seen"], float)
        if len(self.dated) and "own_runs" in state:  # planners saved before the own record was kept have none
            run = np.searchsorted(np.asarray(state["own_runs"], int), np.arange(len(self.dated)), side="right") - 1
            self.dated_own = np.asarray(state["own_actions"], np.float32)[run]
            self._own_known = np.isfinite(self.dated_own).any(axis=0)
        if not len(self.dated) or "dated_bounds" not in state:
            return
        bounds, day = np.asarray(state["dated_bounds"], np.float32), np.asarray(state["dated_weekday"], np.int8)
        if "dated_runs" in state:  # each run holds until the next one starts
            run = np.searchsorted(np.asarray(state["dated_runs"], int), np.arange(len(self.dated)), side="right") - 1
            self.dated, self.dated_weekday = bounds[run], day[run]
            if "dated_applies" in state:
                self.dated_applies = np.asarray(state["dated_applies"], np.int8)[run]
        else:  # the first planners (2026-11-27): the entries that differ from the weekly slots' means
            at = np.asarray(state["dated_at"], int)
            self.dated[at], self.dated_weekday[at] = bounds, day

    def settings(self) -> dict:
        """What `Calendar(**settings)` needs besides `state()`: the export's JSON."""
        clock = None if self.clock is None else self.clock.astype(int).tolist()
        return {"mode": self.mode, "step_minutes": self.step_minutes, "fixed": self.fixed.tolist(),
                "tolerance": self.tolerance, "clock": clock, "occupied_only": self.occupied_only}  # fmt: skip

    @classmethod
    def from_arrays(cls, settings: dict, state: dict) -> Calendar:
        clock = settings.get("clock")
        calendar = cls(settings["mode"], settings["step_minutes"], np.asarray(settings["fixed"], np.float32),
                       settings["tolerance"], None if clock is None else np.asarray(clock, bool),
                       settings.get("occupied_only", False))  # fmt: skip
        calendar.load(state)
        return calendar


class ComfortTimes(Calendar):
    """A building's calendar, learned from the steps the model sees (`learn`)."""

    def __init__(self, building: str | None, step_minutes: float, occupied_only: bool = False):
        from parallel_eplus.buildings.building import load_building

        self.comfort = c = load_building(building).comfort
        mode = THERMOSTAT if c.per_step else ALWAYS if c.always else OBSERVED if c.occupied.observation else CLOCK
        super().__init__(mode, step_minutes, np.array(c.zone_bands, np.float32), c.tolerance, None, occupied_only)
        if mode == CLOCK:  # the spec's hours, at each weekly slot's end (a Monday: weekday 0)
            monday = dt.datetime(2024, 1, 1)
            ends = [monday + dt.timedelta(minutes=step_minutes * k) for k in range(self.slots)]
            self.clock = np.zeros(self.slots, bool)
            self.clock[[self._slot(t) for t in ends]] = [c.applies(t, {}) for t in ends]

    def learn(self, times: list[dt.datetime], applies: np.ndarray, bounds: np.ndarray | None = None) -> None:
        """`bounds` [T, K, 2]: each zone's bounds at those times (per-step thermostat bounds), else None."""
        for i, (t, a) in enumerate(zip(times, applies, strict=True)):
            k = self._slot(t)
            self.seen[k] += 1
            self.applied[k] += bool(a)
            if bounds is not None and self.mode == THERMOSTAT:
                self.bound_sum[k] += bounds[i]
                self.bound_seen[k] += 1
                d = self._date_slot(t)
                self.dated[d], self.dated_weekday[d], self.dated_applies[d] = bounds[i], t.weekday(), bool(a)

    def learn_own(self, times: list[dt.datetime], actions: np.ndarray) -> None:
        """What the building's own controls set (normalized [T, A]) for the steps ending at `times`, by date: the own
        plan of the actions no thermostat schedule gives (a supply-air node: whatever its manager's reset set).
        `learn` records the same dates' weekdays."""
        if not len(self.dated) or not len(times):
            return
        actions = np.asarray(actions, np.float32)
        if self.dated_own.shape[1] != actions.shape[1]:
            self.dated_own = np.full((len(self.dated), actions.shape[1]), np.nan, np.float32)
        self.dated_own[[self._date_slot(t) for t in times]] = actions
        self._own_known = np.isfinite(self.dated_own).any(axis=0)

    def bounds_of(self, values: dict) -> np.ndarray | None:
        """[1, K, 2]: a step's per-zone thermostat bounds from its sensor values (info), or None."""
        if self.mode != THERMOSTAT:
            return None
        return np.array([self.comfort.bounds(values)], float)


def own_reference(bounds: np.ndarray, tolerance: float, sides: list, low: np.ndarray, high: np.ndarray,
                  a_last: np.ndarray, own: np.ndarray | None = None) -> np.ndarray:  # fmt: skip
    """What the building's own controls would set over a horizon, normalized [H, A]: each thermostat action at
    its zone's own setpoint (the bounds `bounds` [H, K, 2], less the tolerance they were widened by), every other
    action at what the own controls set on that date (`own` [H, A], `Calendar.own_actions`: a supply-air node's
    reset), else held at `a_last` [A]. `sides`: per action, (zone, 0 heating or 1 cooling), or None (not a
    thermostat). The planner's `comfort_reference = "baseline"` plays it through the model: a candidate pays only for
    discomfort beyond what these would have from the same state."""
    ref = np.repeat(np.asarray(a_last, np.float32)[None], len(bounds), axis=0)
    if own is not None:
        recorded = np.isfinite(own) & np.array([side is None for side in sides])[None]
        ref = np.where(recorded, own, ref).astype(np.float32)
    for i, side in enumerate(sides):
        if side is not None:
            zone, edge = side
            value = bounds[:, zone, edge] + (tolerance if edge == 0 else -tolerance)
            ref[:, i] = normalize(value, low[i], high[i])
    return np.clip(ref, -1, 1)
