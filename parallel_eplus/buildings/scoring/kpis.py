"""BOPTEST's energy, cost, emissions and peak figures from an episode's step table (docs/kpis.md).

- HVAC energy (`ener_tot`): every fuel's HVAC signal (`[kpis] hvac`, by default the facility's HVAC electricity
  demand: fans, cooling, heating, pumps, heat rejection; never lights or plug loads), kWh, and per m² of floor.
- cost (`cost_tot`): each fuel's HVAC energy times its price when it was used (buildings/pricing/tariff.py: constant,
  day/night, time-of-use periods, or a price series), per m² beside the total;
- the electricity bill (buildings/pricing/bill.py): the facility's energy and demand charges, month by month.
- emissions (`emis_tot`): each fuel's HVAC energy times its factor, kg CO2e, per m² beside the total.
- peak per fuel (`pele_tot`, `pgas_tot`): the highest control-step mean HVAC power, kW (and per m²).
The floor area is the model's own: the conditioned zones EnergyPlus counts in the building's area (eplusout.eio),
times their multipliers; `[kpis] floor_area_m2` overrides it.

Kept light: the EnergyPlus-side process imports scoring/comfort.py, which imports this; pandas is imported only
where a step table is summarized.
"""

from __future__ import annotations

import datetime as dt
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from parallel_eplus.buildings.pricing.bill import DemandTracker, bill_summary
from parallel_eplus.buildings.pricing.tariff import DAY_HOURS, DEFAULT_PRICES, Tariff  # noqa: F401 (their old home)

if TYPE_CHECKING:
    import pandas as pd

# Placeholders where a spec names none (US averages, 2023; say yours in `[kpis]`): kg CO2e per kWh (prices: tariff.py).
DEFAULT_EMISSIONS = {"Electricity": 0.37, "NaturalGas": 0.18}


@dataclass(frozen=True)
class Kpis:
    """A building's HVAC signals per fuel with their prices and emission factors, resolved from its spec."""

    hvac: tuple[tuple[str, str], ...]  # (fuel, step-table column in W)
    tariffs: dict[str, Tariff]
    factors: dict[str, float]
    floor_area_m2: float | None = None

    @classmethod
    def of(cls, spec, hvac: tuple[tuple[str, str], ...]) -> Kpis:
        base = spec.path.parent
        named = dict(spec.kpis.tariff)
        fuels = [f for f, _ in hvac]
        fuels += ["Electricity"] if "Electricity" not in fuels else []  # the bill's, even with no HVAC electricity
        tariffs = {f: Tariff.of(named[f], base) if f in named else Tariff(constant=DEFAULT_PRICES.get(f, 0.0))
                   for f in fuels}  # fmt: skip
        factors = {f: DEFAULT_EMISSIONS.get(f, 0.0) for f in fuels} | dict(spec.kpis.emissions)
        return cls(hvac, tariffs, factors, spec.kpis.floor_area_m2)

    @property
    def reference_price(self) -> float:
        """Electricity's mean price (per kWh): the cost objective's W-equivalents divide by it."""
        ref = self.tariffs.get("Electricity")
        return (ref.mean_price() if ref is not None else 1.0) or 1.0

    def weighted_w(self, values, start: dt.datetime, objective: str) -> float:
        """The reward's energy signal under `objective` (hvac, cost, emissions), in W-equivalents: each fuel's HVAC
        watts weighted by its price (or factor) relative to electricity's mean price, so `power_weight` keeps its
        scale."""
        if objective == "hvac":
            return sum(values[c] for _, c in self.hvac)
        if objective == "cost":
            return sum(values[c] * self.tariffs[f].at(start) for f, c in self.hvac) / self.reference_price
        ref_factor = self.factors.get("Electricity") or 1.0
        return sum(values[c] * self.factors.get(f, 0.0) for f, c in self.hvac) / ref_factor

    def demand_tracker(self, step_minutes: float) -> DemandTracker | None:
        """The demand charges' per-step surrogate (bill.py) for the cost objective; None without demand charges."""
        ref = self.tariffs.get("Electricity")
        return DemandTracker(ref, step_minutes) if ref is not None and ref.demand else None

    def demand_w(self, dollars: float, step_minutes: float) -> float:
        """Demand charges ($) in the reward's W-equivalents: the watts over one step whose energy at electricity's
        mean price costs as much."""
        return dollars / (self.reference_price * step_minutes / 60 / 1000)

    def summarize(self, steps: pd.DataFrame, step_minutes: float, power: str | None = None) -> dict[str, float]:
        """HVAC energy, cost, emissions and peak per fuel over the step table; with `power` (the facility's electric
        demand, W) the electricity bill's parts (bill.py)."""
        hours = step_minutes / 60
        starts = None  # each step's start, for prices that vary in time (~1 ms an episode: only then)
        billed = power is not None and power in steps and "Electricity" in self.tariffs
        if billed or any(self.tariffs[fuel].fixed is None for fuel, _ in self.hvac):
            starts = _index(steps["time"].dt.round("min") - np.timedelta64(int(round(step_minutes)), "m"))
        out: dict[str, float] = {}
        total = cost = emissions = 0.0
        for fuel, col in self.hvac:
            w = np.clip(steps[col].to_numpy(float), 0.0, None)
            kwh = w * hours / 1000
            key = fuel.lower()
            out[f"hvac_{key}_kwh"] = float(kwh.sum())
            out[f"hvac_{key}_peak_kw"] = float(w.max() / 1000) if len(w) else 0.0
            total += float(kwh.sum())
            tariff = self.tariffs[fuel]
            cost += float(np.sum(kwh * (tariff.fixed if tariff.fixed is not None else tariff.series(starts))))
            emissions += float(np.sum(kwh) * self.factors.get(fuel, 0.0))
        out.update(hvac_energy_kwh=total, cost=cost, emissions_kg=emissions)
        if billed:
            out |= bill_summary(self.tariffs["Electricity"], steps[power].to_numpy(float), list(starts.to_pydatetime()),
                                step_minutes)  # fmt: skip
        return out


def _index(starts) -> pd.DatetimeIndex:
    import pandas as pd

    return pd.DatetimeIndex(starts)


PER_AREA = {  # summary key -> its figure per m² of floor (BOPTEST's units)
    "hvac_energy_kwh": "hvac_energy_kwh_m2",
    "energy_kwh": "energy_kwh_m2",
    "cost": "cost_m2",
    "emissions_kg": "emissions_kg_m2",
}


def per_area(summary: dict, area_m2: float | None) -> dict[str, float]:
    """BOPTEST's per-floor-area figures beside the totals (and each fuel's HVAC peak per m²)."""
    if not area_m2:
        return {}
    out = {"floor_area_m2": float(area_m2)}
    out |= {m2: summary[k] / area_m2 for k, m2 in PER_AREA.items() if k in summary}
    out |= {f"{k}_m2": summary[k] / area_m2 for k in summary if k.startswith("hvac_") and k.endswith("_peak_kw")}
    return out


def floor_area(eio: Path) -> float | None:
    """The building's floor area (m²) as EnergyPlus computed it: every zone 'Part of Total Building Area', times
    its zone and zone-list multipliers (eplusout.eio's Zone Information). None: no such file or lines."""
    if not eio.is_file():
        return None
    header: list[str] | None = None
    area = 0.0
    found = False
    with eio.open(errors="replace") as f:
        for line in f:
            if line.startswith("! <Zone Information>"):
                header = [h.strip() for h in line.split(",")]
            elif header and line.startswith(" Zone Information,"):
                row = dict(zip(header, (v.strip() for v in line.split(",")), strict=False))
                if row.get("Part of Total Building Area", "Yes").lower().startswith("y"):
                    mult = float(row.get("Zone Multiplier", 1)) * float(row.get("Zone List Multiplier", 1))
                    area += float(row["Floor Area {m2}"]) * mult
                    found = True
    return area if found else None
