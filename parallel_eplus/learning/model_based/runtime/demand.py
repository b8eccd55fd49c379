"""Demand charges in the planner's cost (`--objective cost` under a tariff with demand charges).

The bill's demand charges (buildings/pricing/bill.py) are per kW of each month's highest 15-minute demand in a charge's
window. The reward prices them with a surrogate that pays a step for raising a month's running peak, and its sum
over a month is the demand charges exactly. The planner prices its horizon the same way: per candidate and charge,
the price times how far the highest predicted facility demand among its horizon's steps in the charge's window
rises above that month's running peak so far (0 where it does not), in the energy term's units (the watts over one
step whose energy at electricity's mean price costs as much, kpis.py's `demand_w`). A plan that pre-cools before
a peak window, or holds a peak below the month's, saves what the bill would.

The running peaks are the facility's own, tracked from each completed step's reading as the reward tracks them
(bill.py's `DemandTracker`, one per worker, reset with its episode). The facility's electric demand must be one of
the model's predicted energy parts (the spec's `power` among its energy terms, as in the offices and every DOE
prototype's starter); where it is not, the planner leaves demand charges out and says so. The demand of a step is
its mean (a 15-minute quarter hour's, for steps of 10 minutes: an approximation the bill does not make), and a
horizon across a month's end takes one highest demand over both months' steps (each against its own month's peak).

Numpy only (and bill.py's, tariff.py's): the served planner builds the same from the contract's tariff, with the
running peaks in the request.
"""

from __future__ import annotations

import datetime as dt
import logging
import math
from dataclasses import dataclass

import numpy as np

from parallel_eplus.buildings.pricing.bill import DemandTracker
from parallel_eplus.buildings.pricing.tariff import Tariff
from parallel_eplus.learning.model_based.runtime.features import step_times

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class DemandCharges:
    """The tariff's demand charges over a horizon: which of a step's predicted energy parts is the facility's
    electric demand (`part`, an index among the state's energy parts), and dollars to the energy term's units."""

    tariff: Tariff
    step_minutes: float
    part: int
    per_dollar: float  # the energy term's W-equivalents per dollar

    @property
    def names(self) -> list[str]:
        return self.tariff.demand_names

    @classmethod
    def of(cls, layout, power: str, objective: str, tariff: Tariff | None, per_dollar: float,
           step_minutes: float) -> DemandCharges | None:  # fmt: skip
        """Under `objective` "cost" with an electricity `tariff` that has demand charges and the facility's demand
        `power` among `layout`'s predicted energy parts; None otherwise. `per_dollar`: the reward's W-equivalents
        of a dollar (kpis.py's `demand_w`)."""
        if objective != "cost" or tariff is None or not tariff.demand:
            return None
        parts = list(layout.state_names[len(layout.temperatures) :])
        if power not in parts:
            log.warning("demand charges: the model does not predict the facility's demand %r (its energy parts: "
                        "%s); the planner's cost leaves them out", power, ", ".join(parts))  # fmt: skip
            return None
        return cls(tariff, step_minutes, parts.index(power), per_dollar)

    def tracker(self) -> DemandTracker:
        return DemandTracker(self.tariff, self.step_minutes)

    def outlook(self, starts: list[dt.datetime], peaks: dict) -> tuple[np.ndarray, np.ndarray]:
        """For steps beginning at `starts`: ([H, C] each charge's price where its window holds the step's start, else
        0; [H, C] the running peak, kW, of that charge in the step's month). `peaks`: (charge, year, month) -> kW,
        a `DemandTracker`'s."""
        prices = np.zeros((len(starts), len(self.tariff.demand)), np.float32)
        running = np.zeros_like(prices)
        for h, t in enumerate(starts):
            for c, d in enumerate(self.tariff.demand):
                if d.window.contains(t):
                    prices[h, c] = d.price
                    running[h, c] = peaks.get((c, t.year, t.month), 0.0)
        return prices, running

    def peaks_of(self, given, when: dt.datetime) -> dict:
        """A request's running peaks (charge name -> kW this month, the served planner's) as a tracker's; a bad one
        raises ValueError("FIELD: why"), FIELD `demand_peaks_kw` or `demand_peaks_kw.NAME`."""
        if given is None:
            return {}
        if not isinstance(given, dict):
            raise ValueError(f"demand_peaks_kw: an object of charge name -> kW, e.g. {{{self.names[0]!r}: 42.0}}")
        unknown = set(given) - set(self.names)
        if unknown:
            raise ValueError(f"demand_peaks_kw: no demand charge named {sorted(unknown)}; the tariff's: {self.names}")
        for name, kw in given.items():
            ok = isinstance(kw, int | float) and not isinstance(kw, bool) and 0 <= kw < 1e12
            if not ok or not math.isfinite(float(kw)):
                raise ValueError(f"demand_peaks_kw.{name}: {kw!r} is not a demand in kW (a finite number >= 0)")
        return {(c, when.year, when.month): float(given[n]) for c, n in enumerate(self.names) if n in given}


@dataclass(frozen=True)
class DemandOutlook:
    """What the planner's cost needs over each worker's horizon: `prices` [W, H, C] ($/kW where each charge's
    window holds a step), `running` [W, H, C] (kW: that month's running peak), the facility demand's `part` and
    `per_dollar` (DemandCharges')."""

    prices: np.ndarray
    running: np.ndarray
    part: int
    per_dollar: float


class DemandWatch:
    """The in-process planner's side: each worker's month of peaks, kept from its meter readings (`column`: the
    facility's demand in the observation), and the charges over its horizon."""

    def __init__(self, charges: DemandCharges, column: int, workers: int):
        self.charges, self.column = charges, column
        self.trackers = [charges.tracker() for _ in range(workers)]

    def reset(self, worker: int) -> None:
        self.trackers[worker].reset()

    def observe(self, obs: np.ndarray, infos: list[dict]) -> None:
        """Each worker's reading of the step that just ended (once per step, however often given)."""
        for i, info in enumerate(infos):
            self.trackers[i].observe(info["time"], float(np.asarray(obs)[i, self.column]))

    def outlook(self, obs: np.ndarray, infos: list[dict], horizon: int) -> DemandOutlook:
        """The charges over each worker's next `horizon` steps, after this step's readings."""
        self.observe(obs, infos)
        prices, running = [], []
        for i, info in enumerate(infos):
            starts = [info["time"], *step_times(info["time"], self.charges.step_minutes, horizon)[:-1]]
            p, r = self.charges.outlook(starts, self.trackers[i].peaks)
            prices.append(p)
            running.append(r)
        c = self.charges
        return DemandOutlook(np.stack(prices), np.stack(running), c.part, c.per_dollar)
