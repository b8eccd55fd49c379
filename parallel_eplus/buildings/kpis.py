"""BOPTEST's energy, cost, emissions and peak figures from an episode's step table (docs/kpis.md).

- HVAC energy (`ener_tot`): every fuel's HVAC signal (`[kpis] hvac`, by default the facility's HVAC electricity
  demand: fans, cooling, heating, pumps, heat rejection; never lights or plug loads), kWh, and per m² of floor.
- cost (`cost_tot`): each fuel's HVAC energy times its price when it was used: constant, day/night, or a price
  series (CSV of `time,price`, held until the next row), per m² beside the total.
- emissions (`emis_tot`): each fuel's HVAC energy times its factor, kg CO2e, per m² beside the total.
- peak per fuel (`pele_tot`, `pgas_tot`): the highest control-step mean HVAC power, kW (and per m²).
The floor area is the model's own: the conditioned zones EnergyPlus counts in the building's area (eplusout.eio),
times their multipliers; `[kpis] floor_area_m2` overrides it.

Kept light: the EnergyPlus-side process imports buildings/comfort.py, which imports this; pandas is imported only
where a step table is summarized.
"""

from __future__ import annotations

import bisect
import csv
import datetime as dt
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:
    import pandas as pd

# Placeholders where a spec names none (US averages, 2023; say yours in `[kpis]`): $ per kWh, kg CO2e per kWh.
DEFAULT_PRICES = {"Electricity": 0.12, "NaturalGas": 0.04}
DEFAULT_EMISSIONS = {"Electricity": 0.37, "NaturalGas": 0.18}
DAY_HOURS = (7.0, 22.0)


@dataclass(frozen=True)
class Tariff:
    """One fuel's price per kWh over time: constant, day/night (`day` within `day_hours`, else `night`), or a series
    (times sorted, each price held until the next)."""

    constant: float | None = None
    day: float = 0.0
    night: float = 0.0
    day_hours: tuple[float, float] = DAY_HOURS
    times: tuple[dt.datetime, ...] = ()
    prices: tuple[float, ...] = ()

    @classmethod
    def of(cls, value: Any, base: Path) -> Tariff:
        if isinstance(value, (int, float)):
            return cls(constant=float(value))
        if "csv" in value:
            return cls.read_csv((base / value["csv"]).expanduser())
        hours = value.get("day_hours", DAY_HOURS)
        return cls(day=float(value["day"]), night=float(value["night"]), day_hours=(float(hours[0]), float(hours[1])))

    @classmethod
    def read_csv(cls, path: Path) -> Tariff:
        """`time,price` rows (ISO times; the year is ignored, so one year's series prices any weather year)."""
        rows = []
        with path.open(newline="") as f:
            for r in csv.DictReader(f):
                t = dt.datetime.fromisoformat(r["time"]).replace(year=2001)
                rows.append((t, float(r["price"])))
        if not rows:
            raise ValueError(f"{path}: no `time,price` rows")
        rows.sort()
        return cls(times=tuple(t for t, _ in rows), prices=tuple(p for _, p in rows))

    def at(self, start: dt.datetime) -> float:
        """The price of a step that began at `start`."""
        if self.constant is not None:
            return self.constant
        if self.times:
            i = bisect.bisect_right(self.times, start.replace(year=2001)) - 1
            return self.prices[max(i, 0)]
        hour = start.hour + start.minute / 60
        return self.day if self.day_hours[0] <= hour < self.day_hours[1] else self.night

    def series(self, starts: pd.DatetimeIndex) -> np.ndarray:
        """The price of each step (vectorized `at`)."""
        if self.constant is not None:
            return np.full(len(starts), self.constant)
        if self.times:
            keys = np.array([t.replace(year=2001) for t in starts.to_pydatetime()], dtype="datetime64[us]")
            i = np.searchsorted(np.array(self.times, dtype="datetime64[us]"), keys, side="right") - 1
            return np.asarray(self.prices)[np.maximum(i, 0)]
        hour = starts.hour.to_numpy() + starts.minute.to_numpy() / 60
        return np.where((hour >= self.day_hours[0]) & (hour < self.day_hours[1]), self.day, self.night)


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
        tariffs = {f: Tariff.of(named[f], base) if f in named else Tariff(constant=DEFAULT_PRICES.get(f, 0.0))
                   for f in fuels}  # fmt: skip
        factors = {f: DEFAULT_EMISSIONS.get(f, 0.0) for f in fuels} | dict(spec.kpis.emissions)
        return cls(hvac, tariffs, factors, spec.kpis.floor_area_m2)

    def weighted_w(self, values, start: dt.datetime, objective: str) -> float:
        """The reward's energy signal under `objective` (hvac, cost, emissions), in W-equivalents: each fuel's HVAC
        watts weighted by its price (or factor) relative to electricity's, so `power_weight` keeps its scale."""
        if objective == "hvac":
            return sum(values[c] for _, c in self.hvac)
        if objective == "cost":
            ref = self.tariffs.get("Electricity")
            ref_price = (ref.at(start) if ref and ref.constant is not None else self._mean_price(ref)) or 1.0
            return sum(values[c] * self.tariffs[f].at(start) for f, c in self.hvac) / ref_price
        ref_factor = self.factors.get("Electricity") or 1.0
        return sum(values[c] * self.factors.get(f, 0.0) for f, c in self.hvac) / ref_factor

    @staticmethod
    def _mean_price(t: Tariff | None) -> float:
        if t is None:
            return 1.0
        if t.times:
            return float(np.mean(t.prices))
        day = (t.day_hours[1] - t.day_hours[0]) / 24
        return day * t.day + (1 - day) * t.night

    def summarize(self, steps: pd.DataFrame, step_minutes: float) -> dict[str, float]:
        """HVAC energy, cost, emissions and peak per fuel over the step table."""
        hours = step_minutes / 60
        starts = None  # each step's start, for prices that vary in time (~1 ms an episode: only then)
        if any(self.tariffs[fuel].constant is None for fuel, _ in self.hvac):
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
            cost += float(np.sum(kwh * (tariff.constant if starts is None else tariff.series(starts))))
            emissions += float(np.sum(kwh) * self.factors.get(fuel, 0.0))
        out.update(hvac_energy_kwh=total, cost=cost, emissions_kg=emissions)
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
