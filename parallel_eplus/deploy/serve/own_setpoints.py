"""The fallback's setpoints: what the building's own controls set at each step of a year, recorded at export.

A served planner that does not trust its answer hands back the building's own setpoints at that date and time
(planner_runtime.py). They are recorded at export by a year of the building's own controls on EnergyPlus (the
schedules of its own thermostats and managers: the model knows them, the planner need not have seen them in
training), and kept step by step, not averaged: a thermostat's fallback is a value its schedule sets (21 °C or
15.6 °C), not a mean of both across an hour or a month (issue 87). A request's date takes the recorded day nearest
it with the same weekday (a schedule's weekday and weekend differ; the record's year need not be the request's),
else, in a record shorter than a week, the nearest recorded day; the time of day, its step.

Stored in planner.npz as runs (each entry holds until the next: a schedule changes a few times a day):
`own_controls` [runs, A] physical, `own_controls_at` [runs] the step of the year each starts at, and
`own_controls_weekday` [366] each recorded day's weekday (-1: not recorded). Planners exported before kept
`own_controls` [12, 24, A], the mean by month and hour: still read so.
Numpy only: the server imports this.
"""

from __future__ import annotations

import datetime as dt

import numpy as np

DAYS = 366


def _day(t: dt.datetime) -> int:
    return t.timetuple().tm_yday - 1


def own_table(times: list[dt.datetime], values: np.ndarray, step_minutes: float) -> dict[str, np.ndarray]:
    """planner.npz's arrays from a record of the own controls: `values` [T, A] physical, set for the steps that start
    at `times` (one weather's, in order)."""
    day_slots = int(round(24 * 60 / step_minutes))
    slots = np.array([_day(t) * day_slots + int((t.hour * 60 + t.minute) // step_minutes) for t in times], int)
    order = np.argsort(slots, kind="stable")
    slots, values = slots[order], np.asarray(values, np.float64)[order]
    starts = np.ones(len(slots), bool)
    starts[1:] = np.any(values[1:] != values[:-1], axis=1)
    weekday = np.full(DAYS, -1, np.int8)
    for t in times:
        weekday[_day(t)] = t.weekday()
    return {"own_controls": values[starts], "own_controls_at": slots[starts].astype(np.int32),
            "own_controls_weekday": weekday}  # fmt: skip


class OwnSetpoints:
    """`own(when)`: the own controls' setpoints [A] (physical) for the step starting at `when`."""

    def __init__(self, arrays: dict, step_minutes: float):
        self.values = np.asarray(arrays["own_controls"], np.float64)
        self.dated = "own_controls_at" in arrays
        if self.dated:
            self.at = np.asarray(arrays["own_controls_at"], int)
            self.weekday = np.asarray(arrays["own_controls_weekday"], int)
            self.days = np.flatnonzero(self.weekday >= 0)
            self.step_minutes, self.day_slots = step_minutes, int(round(24 * 60 / step_minutes))

    def day_of(self, when: dt.datetime) -> int:
        """The recorded day a request at `when` reads: the nearest (around the year) with its weekday, else the
        nearest."""
        distance = np.abs(self.days - _day(when))
        distance = np.minimum(distance, 365 - distance)
        return int(self.days[np.argmin(distance + 1000 * (self.weekday[self.days] != when.weekday()))])

    def __call__(self, when: dt.datetime) -> np.ndarray:
        if not self.dated:  # [12, 24, A]: an export of before 2026-12-07
            return self.values[when.month - 1, when.hour].copy()
        slot = self.day_of(when) * self.day_slots + int((when.hour * 60 + when.minute) // self.step_minutes)
        return self.values[max(int(np.searchsorted(self.at, slot, side="right")) - 1, 0)].copy()
