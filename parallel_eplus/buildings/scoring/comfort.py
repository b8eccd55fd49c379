"""How a building's comfort and energy are scored, per step and per episode: one object for the env, the reward,
the episode summaries, TensorBoard and the evaluation tables.

Comfort is the share of zone samples inside their bounds, counted only where the band applies (an occupied
building; a data center always). The bounds are one band for every zone, a band per zone, or each zone's own
thermostat setpoint schedules read each step (`band = "thermostat"`, buildings/idf/thermostat.py: the occupied and
unoccupied setpoints, as BOPTEST scores). Beside it, the figures BOPTEST reports (Blum et al. 2021, "Building
optimization testing framework (BOPTEST) for simulation-based benchmarking of control strategies"):
- thermal discomfort, K·h per zone: the integral over time of each zone's distance outside its bounds, averaged
  over the zones (BOPTEST's `tdis_tot`); each zone's own integral beside it. Counted while the band applies; with
  thermostat bounds at every step, as BOPTEST does (the bounds are then the setbacks while unoccupied), and
  beside it over the occupied steps alone (`occupied_discomfort_kh`);
- HVAC energy, cost, emissions and peak per fuel (buildings/scoring/kpis.py);
- energy, kWh over the period: every fuel the spec's `energy` observations meter (BOPTEST's `ener_tot`, here
  not divided by floor area);
- peak electric power, kW: the highest control-step mean of the `power` observation (BOPTEST's `pele_tot`
  takes 15-minute means; a control step is 10 or 15 minutes here).
"""

from __future__ import annotations

import datetime as dt
import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from parallel_eplus.buildings.scoring.kpis import Kpis
from parallel_eplus.buildings.spec.load import BuildingSpec, Occupancy

if TYPE_CHECKING:  # the EnergyPlus-side process imports this module: pandas would cost it 0.2 s and 60 MB
    import pandas as pd

APPLIES = "comfort_applies"  # the step table's column: 1 where the band applied to the step, else 0


@dataclass(frozen=True)
class Comfort:
    """A building's reward signals, resolved once from its spec."""

    temperatures: tuple[str, ...]
    band: tuple[float, float]
    power: str  # electric power (W): the peak figure
    energy: tuple[str, ...]  # every fuel (W): the reward's energy term and the energy figure
    occupied: Occupancy | None
    step_minutes: float
    zone_bands: tuple[tuple[float, float], ...] = ()  # fixed bounds per zone (`band` for each if the spec gives one)
    bound_names: tuple[tuple[str, str], ...] | None = None  # per zone: the sensors holding its bounds each step
    kpis: Kpis | None = None
    objective: str = "energy"  # what `energy_w` counts: energy (the spec's `energy`), hvac, cost, emissions
    tolerance: float = 0.0  # K outside the bounds still counted in band (the share only; discomfort is exact)

    @classmethod
    def of(
        cls,
        spec: BuildingSpec,
        steps_per_hour: int,
        bound_names: tuple[tuple[str, str], ...] | None = None,
        hvac: tuple[tuple[str, str], ...] = (),
    ) -> Comfort:
        r = spec.reward
        bands = r.zone_bands or tuple(r.band for _ in r.temperatures)
        kpis = Kpis.of(spec, hvac) if hvac else None
        return cls(
            r.temperatures, r.band, r.power, r.energy_terms, r.occupied, 60.0 / steps_per_hour, bands, bound_names,
            kpis, r.objective, r.tolerance,
        )  # fmt: skip

    @property
    def always(self) -> bool:
        return self.occupied is None

    @property
    def per_step(self) -> bool:
        """Whether the bounds change from step to step (read from the model's thermostat schedules)."""
        return self.bound_names is not None

    def bounds(self, values: Mapping[str, float]) -> tuple[tuple[float, float], ...]:
        """Each zone's (lower, upper) bound at the step whose observations are `values`."""
        if self.bound_names is None:
            return self.zone_bands
        return tuple((values[lo], values[hi]) for lo, hi in self.bound_names)

    def applies(self, time: dt.datetime, values: Mapping[str, float]) -> bool:
        """Whether the band applies to the step that ended at `time` (values: the step's observations by name)."""
        o = self.occupied
        if o is None:
            return True
        if o.observation is not None:
            return values[o.observation] > o.above
        start = time - dt.timedelta(minutes=self.step_minutes)  # the step began here; `time` is its end
        hour = start.hour + start.minute / 60
        return start.weekday() in o.weekdays and o.hours[0] <= hour < o.hours[1]

    def energy_w(self, values: Mapping[str, float]) -> float:
        """The reward's energy signal (W) under the objective; `values` holds the step's `time` for a tariff."""
        if self.objective != "energy" and self.kpis is not None:
            start = values["time"] - dt.timedelta(minutes=self.step_minutes)
            return self.kpis.weighted_w(values, start, self.objective)
        if len(self.energy) == 1:
            return values[self.energy[0]]
        return math.fsum(values[e] for e in self.energy)

    def demand_tracker(self):
        """Under the cost objective with demand charges, the episode's per-step surrogate of them (bill.py); else
        None."""
        if self.objective != "cost" or self.kpis is None:
            return None
        return self.kpis.demand_tracker(self.step_minutes)

    def demand_w(self, tracker, values: Mapping[str, float]) -> tuple[float, float]:
        """The demand charges ($) the step whose observations are `values` adds, and as the reward's W-equivalents
        (added to `energy_w`): the surrogate's share of the month's demand charges."""
        start = values["time"] - dt.timedelta(minutes=self.step_minutes)
        dollars = tracker.step(start, values[self.power])
        return dollars, self.kpis.demand_w(dollars, self.step_minutes)

    def outside(self, temps: tuple[float, ...], bounds=None) -> int:
        """Zones outside their bounds widened by `tolerance`: what the share in band (`summarize`) counts as out.
        `train --algorithm mpc` first counted against the bare bounds, where thermostat controls sit: on a
        building scored with 0.2 K of tolerance its multiplier saw more samples out than any evaluation did."""
        tol, pairs = self.tolerance, zip(temps, bounds or self.zone_bands, strict=True)
        return sum(not low - tol <= t <= high + tol for t, (low, high) in pairs)  # a NaN reading: out

    def cost(self, temps: tuple[float, ...], margin_c: float, bounds=None) -> tuple[float, int]:
        """A step's comfort cost where the band applies (learning/lagrangian.py): per zone 0 inside its scored edges
        (its bounds widened by `tolerance`, as the share in band counts them) shrunk by `margin_c` on each side,
        rising linearly to 1 at those edges and 1 beyond, averaged over the zones; and the number of zones outside
        the edges. `bounds`: this step's (`bounds`); None: fixed. With thermostat bounds the built-in controls hold
        a zone on its bound: inside the scored edges, they pay nothing for it once the margin is below the
        tolerance."""
        total, out, tol = 0.0, 0, self.tolerance
        for t, (low, high) in zip(temps, bounds or self.zone_bands, strict=True):
            d = max(low - tol + margin_c - t, t - high - tol + margin_c, 0.0) / margin_c
            total += d if d < 1.0 else 1.0
            out += not low - tol <= t <= high + tol
        return total / len(temps), out

    def summarize(self, steps: pd.DataFrame) -> dict[str, float]:
        """An episode's comfort and energy figures from its step table (`zone` names drop `_temp_c`)."""
        out: dict[str, float] = {}
        hours = self.step_minutes / 60
        applies = steps[APPLIES].to_numpy(bool) if APPLIES in steps else np.ones(len(steps), bool)
        out["comfort_steps_pct"] = float(100 * applies.mean())
        energy = sum(steps[e].to_numpy(float) for e in self.energy)
        out["energy_kwh"] = float(np.sum(energy) * hours / 1000)
        out["peak_power_kw"] = float(steps[self.power].max() / 1000)
        if self.kpis is not None and all(c in steps for _, c in self.kpis.hvac):
            out.update(self.kpis.summarize(steps, self.step_minutes, self.power))
        in_band, discomfort, occupied = [], [], []
        for k, col in enumerate(self.temperatures):
            zone = col.removesuffix("_temp_c")
            low, high = self._bound_columns(steps, k)
            every = steps[col].to_numpy(float)
            t = every[applies]
            if t.size:
                out[f"{zone}_temp_mean"] = float(t.mean())
                out[f"{zone}_temp_std"] = float(t.std())
                out[f"{zone}_temp_min"] = float(t.min())
                out[f"{zone}_temp_max"] = float(t.max())
            lo, hi = (low[applies], high[applies]) if np.ndim(low) else (low, high)
            ok = (t >= lo - self.tolerance) & (t <= hi + self.tolerance)
            out[f"{zone}_in_band_pct"] = float(100 * ok.mean()) if t.size else float("nan")
            in_use = float(np.sum(np.maximum(lo - t, 0) + np.maximum(t - hi, 0)) * hours)
            if self.per_step:  # BOPTEST's tdis: every step, against the occupied and unoccupied setpoints
                kh = float(np.sum(np.maximum(low - every, 0) + np.maximum(every - high, 0)) * hours)
            else:
                kh = in_use
            out[f"{zone}_discomfort_kh"] = kh
            in_band.append(ok)
            discomfort.append(kh)
            occupied.append(in_use)
        both = np.concatenate(in_band) if in_band else np.zeros(0, bool)
        out["in_band_pct"] = float(100 * both.mean()) if both.size else float("nan")
        out["discomfort_kh"] = float(np.mean(discomfort)) if discomfort else 0.0  # per zone, as BOPTEST's tdis_tot
        if self.per_step:  # and while the band applies alone: what a goal of "no more occupied discomfort" counts
            out["occupied_discomfort_kh"] = float(np.mean(occupied)) if occupied else 0.0
        return out

    def _bound_columns(self, steps: pd.DataFrame, k: int):
        """Zone k's bounds over the step table: two arrays (read each step) or two numbers."""
        if self.bound_names is None:
            return self.zone_bands[k]
        lo, hi = self.bound_names[k]
        return steps[lo].to_numpy(float), steps[hi].to_numpy(float)
