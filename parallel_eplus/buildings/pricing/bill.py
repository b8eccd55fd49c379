"""The facility's electricity bill under its tariff, month by month, and the reward's per-step share of it.

- energy charges: each control step's facility electricity (the reward's `power`, kWh) times the price when the
  step began;
- demand charges: for each demand charge and month, its price per kW times the month's highest 15-minute mean
  demand among the clock's quarter hours (:00, :15, :30, :45) that start within its window. A quarter hour is the
  mean of the steps covering it (10-minute steps: a quarter hour takes one step whole and half of the next); only
  whole quarter hours count, so a bill and the surrogate below agree to the cent;
- the surrogate (`DemandTracker`, for `--objective cost`): at each step, the charge added by the quarter hours it
  completes, i.e. price x how far each one's mean rises above the month's running peak in its window. A month's
  running peak starts at 0 and only rises, so the surrogate's sum over a month is exactly its demand charges
  (the increments telescope to the final peak); it pays a step for raising the peak when it does, which is when
  the action that raised it was taken.
The bill is the facility's meter, lights and plugs included (the utility's bill); BOPTEST's `cost` (kpis.py) counts
HVAC energy only.
"""

from __future__ import annotations

import datetime as dt
import math
from collections.abc import Sequence

import numpy as np

from parallel_eplus.buildings.pricing.tariff import Tariff

QUARTER = 15  # minutes: the demand interval


def _pieces(step_minutes: float) -> tuple[int, int]:
    """(minutes per piece, pieces per quarter hour): the steps cut into pieces that tile both steps and quarters."""
    g = math.gcd(int(round(step_minutes)), QUARTER)
    return g, QUARTER // g


def quarter_hours(power_w: np.ndarray, starts: Sequence[dt.datetime], step_minutes: float):
    """(each whole quarter hour's start, its mean demand in kW) from the steps' mean power and start times."""
    g, per = _pieces(step_minutes)
    n = int(round(step_minutes)) // g
    kw = np.repeat(np.asarray(power_w, float) / 1000, n)
    t0 = np.repeat(np.array(starts, dtype="datetime64[m]"), n) + np.tile(np.arange(n) * g, len(starts)).astype(
        "timedelta64[m]")  # fmt: skip
    quarter = t0.astype("datetime64[m]").astype(np.int64) // QUARTER
    keys, first, counts = np.unique(quarter, return_index=True, return_counts=True)
    sums = np.add.reduceat(kw, first) if len(kw) else np.zeros(0)
    whole = counts == per
    begins = (keys[whole] * QUARTER).astype("datetime64[m]").astype(dt.datetime)
    return list(begins), sums[whole] / per


def monthly_bill(tariff: Tariff, power_w: np.ndarray, starts: Sequence[dt.datetime], step_minutes: float) -> dict:
    """{month "MM": {"energy": $, "demand": $, "peak_kw": the month's highest quarter hour}} over the steps."""
    hours = step_minutes / 60
    kwh = np.clip(np.asarray(power_w, float), 0, None) * hours / 1000
    prices = tariff.series(list(starts))
    months = np.array([t.month for t in starts])
    out: dict[str, dict[str, float]] = {}
    for m in sorted(set(months.tolist())):
        sel = months == m
        out[f"{m:02d}"] = {"energy": float(np.sum(kwh[sel] * prices[sel])), "demand": 0.0, "peak_kw": 0.0}
    begins, kw = quarter_hours(np.clip(np.asarray(power_w, float), 0, None), starts, step_minutes)
    if not begins:
        return out
    qmonth = np.array([t.month for t in begins])
    hour = np.array([t.hour + t.minute / 60 for t in begins])
    weekday = np.array([t.weekday() for t in begins])
    for m in sorted(set(qmonth.tolist())):
        sel = qmonth == m
        month = out.setdefault(f"{m:02d}", {"energy": 0.0, "demand": 0.0, "peak_kw": 0.0})
        month["peak_kw"] = float(kw[sel].max())
        for d in tariff.demand:
            inside = sel & d.window.mask(hour, weekday, qmonth)
            month["demand"] += d.price * float(kw[inside].max()) if inside.any() else 0.0
    return out


def bill_summary(tariff: Tariff, power_w: np.ndarray, starts: Sequence[dt.datetime], step_minutes: float) -> dict:
    """The summary's bill figures: `bill`, `bill_energy`, `bill_demand`, and per month `bill_energy_MM`,
    `bill_demand_MM`, `peak_15min_kw_MM`; `peak_15min_kw` the highest quarter hour of all."""
    months = monthly_bill(tariff, power_w, starts, step_minutes)
    out: dict[str, float] = {}
    for m, b in months.items():
        out |= {f"bill_energy_{m}": b["energy"], f"bill_demand_{m}": b["demand"], f"peak_15min_kw_{m}": b["peak_kw"]}
    energy = sum(b["energy"] for b in months.values())
    demand = sum(b["demand"] for b in months.values())
    peak = max((b["peak_kw"] for b in months.values()), default=0.0)
    return out | {"bill": energy + demand, "bill_energy": energy, "bill_demand": demand, "peak_15min_kw": peak}


class DemandTracker:
    """The demand charges' per-step surrogate for the reward (see the module's docstring); one per episode."""

    def __init__(self, tariff: Tariff, step_minutes: float):
        self.tariff, self.step_minutes = tariff, step_minutes
        self.piece, self.per = _pieces(step_minutes)
        self.reset()

    def reset(self) -> None:
        self.quarter: int | None = None  # the open quarter hour (minutes since the epoch // 15), its pieces' kW
        self.kw: list[float] = []
        self.peaks: dict[tuple[int, int, int], float] = {}  # (charge, year, month) -> running peak, kW
        self.last_end: dt.datetime | None = None  # when the last step `observe` was given ended

    def observe(self, end: dt.datetime, power_w: float) -> None:
        """A reading of the step that ended at `end`, as a planner or its client sees the meter: each step once
        however often it is read, and an episode's first reading (the end of its warm-up, no step of its own: the
        reward's peaks start at 0 too) only marks the time."""
        if self.last_end is not None and end > self.last_end:
            self.step(end - dt.timedelta(minutes=self.step_minutes), power_w)
        if self.last_end is None or end > self.last_end:
            self.last_end = end

    def month_peaks(self, names: Sequence[str], when: dt.datetime) -> dict[str, float]:
        """The running peaks of the month of `when` by charge name (`names`: the tariff's charges in order), kW:
        what a served planner's request carries (`demand_peaks_kw`)."""
        return {n: self.peaks[(c, when.year, when.month)] for c, n in enumerate(names)
                if (c, when.year, when.month) in self.peaks}  # fmt: skip

    def step(self, start: dt.datetime, power_w: float) -> float:
        """The demand charges ($) the quarter hours completed by this step (which began at `start`) add."""
        charge = 0.0
        minutes = int(np.datetime64(start, "m").astype(np.int64))
        for k in range(int(round(self.step_minutes)) // self.piece):
            at = minutes + k * self.piece
            if at // QUARTER != self.quarter:
                self.quarter, self.kw = at // QUARTER, []
            self.kw.append(max(power_w, 0.0) / 1000)
            if len(self.kw) == self.per:
                charge += self._close(self.quarter * QUARTER, sum(self.kw) / self.per)
        return charge

    def _close(self, minutes: int, kw: float) -> float:
        begin = np.datetime64(minutes, "m").astype(dt.datetime)
        charge = 0.0
        for i, d in enumerate(self.tariff.demand):
            if d.window.contains(begin):
                key = (i, begin.year, begin.month)
                rise = kw - self.peaks.get(key, 0.0)
                if rise > 0:
                    charge += d.price * rise
                    self.peaks[key] = kw
        return charge
