"""How a building's comfort and energy are scored, per step and per episode: one object for the env, the reward,
the episode summaries, TensorBoard and the evaluation tables.

Comfort is the share of zone samples inside the band, counted only where the band applies (an occupied
building; a data center always). Beside it, the figures BOPTEST reports (Blum et al. 2021, "Building
optimization testing framework (BOPTEST) for simulation-based benchmarking of control strategies"):
- thermal discomfort, K·h per zone: the integral over time of each zone's distance outside the band while it
  applies, averaged over the zones (BOPTEST's `tdis_tot`); each zone's own integral beside it;
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

from parallel_eplus.buildings.spec import BuildingSpec, Occupancy

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

    @classmethod
    def of(cls, spec: BuildingSpec, steps_per_hour: int) -> Comfort:
        r = spec.reward
        return cls(r.temperatures, r.band, r.power, r.energy_terms, r.occupied, 60.0 / steps_per_hour)

    @property
    def always(self) -> bool:
        return self.occupied is None

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
        if len(self.energy) == 1:
            return values[self.energy[0]]
        return math.fsum(values[e] for e in self.energy)

    def out_of_band(self, temps: tuple[float, ...]) -> tuple[int, float]:
        """(zones outside the band, their summed distance outside it in K)."""
        low, high = self.band
        n, dist = 0, 0.0
        for t in temps:
            if t < low:
                n, dist = n + 1, dist + low - t
            elif t > high:
                n, dist = n + 1, dist + t - high
        return n, dist

    def cost(self, temps: tuple[float, ...], margin_c: float) -> tuple[float, int]:
        """A step's comfort cost where the band applies (learning/lagrangian.py): per zone 0 inside the band shrunk
        by `margin_c` on each side, rising linearly to 1 at the band's edge and 1 beyond, averaged over the zones;
        and the number of zones outside the band itself."""
        low, high = self.band
        total, out = 0.0, 0
        for t in temps:
            d = max(low + margin_c - t, t - high + margin_c, 0.0) / margin_c
            total += d if d < 1.0 else 1.0
            out += t < low or t > high
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
        low, high = self.band
        in_band, discomfort = [], []
        for col in self.temperatures:
            zone = col.removesuffix("_temp_c")
            t = steps[col].to_numpy(float)[applies]
            if t.size:
                out[f"{zone}_temp_mean"] = float(t.mean())
                out[f"{zone}_temp_std"] = float(t.std())
                out[f"{zone}_temp_min"] = float(t.min())
                out[f"{zone}_temp_max"] = float(t.max())
            ok = (t >= low) & (t <= high)
            out[f"{zone}_in_band_pct"] = float(100 * ok.mean()) if t.size else float("nan")
            kh = float(np.sum(np.maximum(low - t, 0) + np.maximum(t - high, 0)) * hours)
            out[f"{zone}_discomfort_kh"] = kh
            in_band.append(ok)
            discomfort.append(kh)
        both = np.concatenate(in_band) if in_band else np.zeros(0, bool)
        out["in_band_pct"] = float(100 * both.mean()) if both.size else float("nan")
        out["discomfort_kh"] = float(np.mean(discomfort)) if discomfort else 0.0  # per zone, as BOPTEST's tdis_tot
        return out
