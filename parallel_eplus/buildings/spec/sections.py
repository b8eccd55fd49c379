"""The spec's optional sections, each parsed on its own: forecasts, when comfort counts, per-zone bands, KPIs.

Each parser appends every problem it finds to `errors` (the loader reports them all at once) and returns what it
could read.
"""

from __future__ import annotations

import difflib
from pathlib import Path
from typing import Any

from parallel_eplus.buildings.pricing.tariff import check_tariff, load_tariff_file
from parallel_eplus.buildings.spec.records import (
    OCCUPANCY_OBSERVATION,
    THERMOSTAT,
    WEEKDAYS,
    KpiSpec,
    Observation,
    Occupancy,
)
from parallel_eplus.buildings.weather.forecast_features import ForecastSpec


def did_you_mean(value: str, names) -> str:
    """'; close: "NAME"' for the nearest of `names`, for an error message; empty when none is near."""
    match = difflib.get_close_matches(value, list(names), n=1)
    return f'; close: "{match[0]}"' if match else ""


FORECAST_KEYS = {"name", "forecast", "hours", "steps", "stride", "error", "low", "high"}


def parse_forecast(t: dict[str, Any], where: str, errors: list[str]) -> list[ForecastSpec]:
    """`{ name = "outdoor_next", forecast = "drybulb", hours = 6 }`: the next 6 hours of the EPW's dry bulb;
    `steps = 8` instead counts control steps; `stride` (default 1, in the same unit); `error = "low"`, "medium"
    or "high" adds BOPTEST's forecast error; `low`/`high`: the bounds (default the EPW's, -70 and 70)."""
    unknown = sorted(set(t) - FORECAST_KEYS)
    if unknown:
        errors.append(f"{where[:-1]}: unknown key(s) {unknown}; a forecast takes {sorted(FORECAST_KEYS)}")
    if ("hours" in t) == ("steps" in t):
        errors.append(f"{where[:-1]}: a forecast gives either hours or steps (how many values)")
        return []
    count = t.get("hours", t.get("steps"))
    try:
        return [ForecastSpec(str(t.get("name", t["forecast"])), str(t["forecast"]), int(count),
                             float(t.get("stride", 1)), "steps" in t, t.get("error"),
                             float(t.get("low", -70.0)), float(t.get("high", 70.0)))]  # fmt: skip
    except (ValueError, TypeError) as e:
        errors.append(f"{where}forecast: {e}")
        return []


def parse_occupancy(table: Any, observations: list[Observation], errors: list[str]) -> Occupancy | None:
    """`reward.occupied`: { schedule = NAME } (its value, read each step, added as the `occupancy` observation
    unless one reads it already), { observation = NAME }, or { hours = [start, end], weekdays = ["Mon", ...] }."""
    where = "reward.occupied"
    if not isinstance(table, dict):
        errors.append(f'{where}: {table!r} is not a table such as {{ schedule = "OCC_SCH" }}')
        return None
    unknown = set(table) - {"schedule", "observation", "above", "hours", "weekdays", "high"}
    if unknown:
        errors.append(f"{where}: unknown key(s) {sorted(unknown)}; use schedule, observation, above, hours, weekdays")
    kinds = [k for k in ("schedule", "observation", "hours") if k in table]
    if len(kinds) != 1:
        errors.append(f"{where}: give one of schedule, observation or hours (got {kinds or 'none'})")
        return None
    above = table.get("above", 0.0)
    if not isinstance(above, (int, float)) or isinstance(above, bool):
        errors.append(f"{where}.above: {above!r} is not a number")
        above = 0.0
    if "hours" in table:
        hours, days = table["hours"], table.get("weekdays", list(WEEKDAYS))
        if not (isinstance(hours, list) and len(hours) == 2 and all(isinstance(h, (int, float)) for h in hours)
                and 0 <= hours[0] < hours[1] <= 24):  # fmt: skip
            errors.append(f"{where}.hours: {hours!r} is not [start, end] with 0 <= start < end <= 24")
            hours = [0, 24]
        bad = [d for d in days if d not in WEEKDAYS] if isinstance(days, list) else [days]
        if bad:
            errors.append(f"{where}.weekdays: {bad} not among {list(WEEKDAYS)}")
            days = list(WEEKDAYS)
        return Occupancy(hours=(float(hours[0]), float(hours[1])), weekdays=tuple(WEEKDAYS.index(d) for d in days))
    if "observation" in table:
        name = table["observation"]
        names = [o.name for o in observations]
        if name not in names:
            errors.append(f'{where}.observation: "{name}" is not an observation name{did_you_mean(str(name), names)}')
        return Occupancy(observation=str(name), above=float(above))
    schedule = table["schedule"]
    if not isinstance(schedule, str) or not schedule:
        errors.append(f"{where}.schedule: {schedule!r} is not a schedule name")
        return None
    for o in observations:  # an observation reading this schedule already
        if o.variable == "Schedule Value" and (o.key or "").lower() == schedule.lower():
            return Occupancy(observation=o.name, above=float(above))
    if any(o.name == OCCUPANCY_OBSERVATION for o in observations):
        errors.append(
            f'{where}.schedule: an observation is named "{OCCUPANCY_OBSERVATION}" already; read the schedule there '
            '(variable = "Schedule Value") and give occupied = { observation = ... }'
        )
        return None
    high = float(table.get("high", 1.0))  # a fraction schedule; a head-count one gives its maximum
    observations.append(Observation(OCCUPANCY_OBSERVATION, 0.0, high, "Schedule Value", schedule))
    return Occupancy(observation=OCCUPANCY_OBSERVATION, above=float(above))


def parse_band(value: Any, temps: list[str], errors: list[str]):
    """`reward.band`: [low, high] for every zone, { zone = [low, high], ... } per zone (every temperature named),
    or "thermostat". Returns (band, zone bands or None, thermostat)."""
    where = "reward.band"

    def pair(v, at) -> list[float]:
        if not (isinstance(v, list) and len(v) == 2 and all(isinstance(x, (int, float)) for x in v) and v[0] < v[1]):
            errors.append(f"{at}: {v!r} is not [low, high] with low below high")
            return [0.0, 1.0]
        return [float(v[0]), float(v[1])]

    if value is None:
        errors.append(f'{where}: missing ([low, high], {{ zone = [low, high], ... }} or "{THERMOSTAT}")')
        return [0.0, 1.0], None, False
    if value == THERMOSTAT:
        return [20.0, 25.0], None, True
    if isinstance(value, dict):
        unknown = [k for k in value if k not in temps]
        for k in unknown:
            errors.append(f"{where}.{k}: not among reward.temperatures{did_you_mean(k, temps)}")
        missing = [t for t in temps if t not in value]
        if missing:
            errors.append(f"{where}: no band for {missing}")
        zones = tuple(tuple(pair(value[t], f"{where}.{t}")) for t in temps if t in value)
        if not zones:
            return [0.0, 1.0], None, False
        return [min(z[0] for z in zones), max(z[1] for z in zones)], zones, False
    if isinstance(value, str):
        errors.append(f'{where}: {value!r} is not "{THERMOSTAT}", [low, high] or a table of zones')
        return [0.0, 1.0], None, False
    return pair(value, where), None, False


def parse_kpis(table: Any, obs_names: list[str], errors: list[str], base: Path | None = None) -> KpiSpec:
    """`[kpis]` (all optional): hvac, tariff, emissions per fuel; floor_area_m2. A tariff's `file` is read here
    (relative to `base`, the spec's folder, or a built-in tariff), so its problems are the spec's."""
    if not isinstance(table, dict):
        errors.append(f"kpis: {table!r} is not a table")
        return KpiSpec()
    unknown = set(table) - {"hvac", "tariff", "emissions", "floor_area_m2"}
    if unknown:
        errors.append(f"kpis: unknown key(s) {sorted(unknown)}; use hvac, tariff, emissions, floor_area_m2")
    tables = {}
    for key in ("hvac", "tariff", "emissions"):
        t = table.get(key, {})
        if not isinstance(t, dict):
            errors.append(f"kpis.{key}: {t!r} is not a table of fuels, e.g. {{ Electricity = ..., NaturalGas = ... }}")
            t = {}
        tables[key] = t
    for fuel, source in tables["hvac"].items():
        if not isinstance(source, str) or not source:
            errors.append(f"kpis.hvac.{fuel}: {source!r} is not an observation, meter or variable name")
    for fuel, factor in tables["emissions"].items():
        if not isinstance(factor, (int, float)) or isinstance(factor, bool) or factor < 0:
            errors.append(f"kpis.emissions.{fuel}: {factor!r} is not kg CO2e per kWh (a number >= 0)")
    for fuel, price in list(tables["tariff"].items()):
        where = f"kpis.tariff.{fuel}"
        if isinstance(price, dict) and "file" in price:
            loaded = load_tariff_file(price, base or Path.cwd(), where, errors)
            if loaded is None:
                continue
            tables["tariff"][fuel] = price = loaded
            where += f" ({price.get('name') or 'file'})"
        check_tariff(price, where, errors, fuel == "Electricity")
    area = table.get("floor_area_m2")
    if area is not None and not (isinstance(area, (int, float)) and area > 0):
        errors.append(f"kpis.floor_area_m2: {area!r} is not a positive number")
        area = None
    return KpiSpec(
        tuple((f, str(v)) for f, v in tables["hvac"].items()),
        tuple(tables["tariff"].items()),
        tuple((f, float(v)) for f, v in tables["emissions"].items() if isinstance(v, (int, float))),
        float(area) if area else None,
    )
