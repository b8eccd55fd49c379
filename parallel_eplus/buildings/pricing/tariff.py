"""One fuel's prices: energy charges per kWh over time and demand charges per kW of a month's peak (docs/kpis.md).

A spec's `[kpis] tariff` names, per fuel, a constant price, a day/night price, a CSV price series, or a table:
`price` (per kWh, where no period applies), `periods` (time-of-use windows with their own price; the first that
holds a step prices it), `demand` (charges per kW of the month's highest 15-minute mean demand, each over its
window), or `file` (such a table in a TOML file of its own; `tariffs/` ships BOPTEST's scenarios and an example
commercial tariff). A window is hours [start, end) of the day (start > end wraps past midnight; several ranges:
[[8, 12], [18, 21]]), weekdays and months, each optional. `price_outlook` prices any future step for a planner.

Kept light (numpy only): the EnergyPlus-side process imports buildings/scoring/comfort.py, which imports this.
"""

from __future__ import annotations

import csv
import datetime as dt
import tomllib
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path
from typing import Any

import numpy as np

from parallel_eplus.buildings.clock import WEEKDAYS

DAY_HOURS = (7.0, 22.0)
DEFAULT_PRICES = {"Electricity": 0.12, "NaturalGas": 0.04}  # $/kWh where a spec names none (US averages, 2023)
ENERGY_FORMS = ({"price"}, {"day", "night"}, {"csv"})  # one of these gives the energy price
KEYS = {"price", "periods", "day", "night", "day_hours", "weekdays_only", "csv", "demand", "file", "name", "source"}
WINDOW_KEYS = {"price", "hours", "weekdays", "months", "name"}


@dataclass(frozen=True)
class Window:
    """When a price or a demand charge applies; None: always (along that axis)."""

    hours: tuple[tuple[float, float], ...] | None = None  # [start, end) hours of the day, one range or several;
    # start > end wraps past midnight
    weekdays: tuple[int, ...] | None = None  # 0 = Monday
    months: tuple[int, ...] | None = None  # 1 = January

    def contains(self, t: dt.datetime) -> bool:
        return bool(self.mask(np.array([t.hour + t.minute / 60]), np.array([t.weekday()]), np.array([t.month]))[0])

    def mask(self, hour: np.ndarray, weekday: np.ndarray, month: np.ndarray) -> np.ndarray:
        ok = np.ones(len(hour), bool)
        if self.hours is not None:
            inside = np.zeros(len(hour), bool)
            for a, b in self.hours:
                inside |= (hour >= a) & (hour < b) if a < b else (hour >= a) | (hour < b)
            ok &= inside
        if self.weekdays is not None:
            ok &= np.isin(weekday, self.weekdays)
        if self.months is not None:
            ok &= np.isin(month, self.months)
        return ok

    @classmethod
    def of(cls, t: dict) -> Window:
        hours = t.get("hours")
        ranges = [hours] if hours and not isinstance(hours[0], list) else hours or []
        return cls(
            tuple((float(a), float(b)) for a, b in ranges) if hours is not None else None,
            tuple(WEEKDAYS.index(d) for d in t["weekdays"]) if "weekdays" in t else None,
            tuple(int(m) for m in t["months"]) if "months" in t else None,
        )


@dataclass(frozen=True)
class Period:
    price: float  # per kWh
    window: Window


@dataclass(frozen=True)
class DemandCharge:
    """Per kW of the month's highest 15-minute mean demand within its window."""

    price: float
    window: Window
    name: str = ""


@dataclass(frozen=True)
class Tariff:
    """One fuel's price per kWh over time (constant; day/night; a series, each price held until the next; or a base
    price with time-of-use periods) and its demand charges."""

    constant: float | None = None  # the price, or with `periods` the price where none applies
    day: float = 0.0
    night: float = 0.0
    day_hours: tuple[float, float] = DAY_HOURS
    times: tuple[dt.datetime, ...] = ()
    prices: tuple[float, ...] = ()
    periods: tuple[Period, ...] = ()
    demand: tuple[DemandCharge, ...] = ()
    weekdays_only: bool = False  # day/night: the day price on weekdays only
    name: str = ""

    @property
    def demand_names(self) -> list[str]:
        """Each demand charge's name (`charge K` where it has none): how requests and peaks name them."""
        return [d.name or f"charge {i}" for i, d in enumerate(self.demand)]

    @property
    def fixed(self) -> float | None:
        """The price when it never changes, else None."""
        return self.constant if not self.periods else None

    @classmethod
    def of(cls, value: Any, base: Path) -> Tariff:
        """From a spec's value (checked by `check_tariff`); files relative to `base`."""
        if isinstance(value, (int, float)):
            return cls(constant=float(value))
        demand = tuple(DemandCharge(float(d["price"]), Window.of(d), str(d.get("name", "")))
                       for d in value.get("demand", ()))  # fmt: skip
        name = str(value.get("name", ""))
        if "csv" in value:
            times, prices = read_csv((base / value["csv"]).expanduser())
            return cls(times=times, prices=prices, demand=demand, name=name)
        if "day" in value:
            hours = value.get("day_hours", DAY_HOURS)
            return cls(day=float(value["day"]), night=float(value["night"]),
                       day_hours=(float(hours[0]), float(hours[1])), weekdays_only=bool(value.get("weekdays_only")),
                       demand=demand, name=name)  # fmt: skip
        periods = tuple(Period(float(p["price"]), Window.of(p)) for p in value.get("periods", ()))
        return cls(constant=float(value["price"]), periods=periods, demand=demand, name=name)

    def at(self, start: dt.datetime) -> float:
        """The price of a step that began at `start`."""
        return float(self.series([start])[0])

    def series(self, starts) -> np.ndarray:
        """The price of each step (its start: datetimes, or a pandas DatetimeIndex)."""
        starts = list(starts.to_pydatetime()) if hasattr(starts, "to_pydatetime") else list(starts)
        if self.fixed is not None:
            return np.full(len(starts), self.fixed)
        if self.times:
            keys = np.array([t.replace(year=2001) for t in starts], dtype="datetime64[us]")
            i = np.searchsorted(np.array(self.times, dtype="datetime64[us]"), keys, side="right") - 1
            return np.asarray(self.prices)[np.maximum(i, 0)]
        hour, weekday, month = _clock(starts)
        if self.periods:
            out = np.full(len(starts), float(self.constant))
            done = np.zeros(len(starts), bool)
            for p in self.periods:
                m = p.window.mask(hour, weekday, month) & ~done
                out[m], done = p.price, done | m
            return out
        day = (hour >= self.day_hours[0]) & (hour < self.day_hours[1])
        if self.weekdays_only:
            day &= weekday < 5
        return np.where(day, self.day, self.night)

    def demand_rates(self, starts) -> tuple[np.ndarray, np.ndarray]:
        """Per step: the demand charges ($/kW) whose window holds it, summed, and whether a windowed one (an on-peak
        charge, not an any-time one) does."""
        starts = list(starts.to_pydatetime()) if hasattr(starts, "to_pydatetime") else list(starts)
        hour, weekday, month = _clock(starts)
        rate, on_peak = np.zeros(len(starts)), np.zeros(len(starts), bool)
        for d in self.demand:
            m = d.window.mask(hour, weekday, month)
            rate += np.where(m, d.price, 0.0)
            on_peak |= m & (d.window != Window())
        return rate, on_peak

    def mean_price(self) -> float:
        """The mean price over a year's hours (the reward's reference for cost in W-equivalents)."""
        return self._mean_price

    @cached_property
    def _mean_price(self) -> float:  # once per tariff: a year of hours costs ~40 ms, and the reward asks every step
        if self.fixed is not None:
            return self.fixed
        if self.times:
            return float(np.mean(self.prices))
        year = [dt.datetime(2013, 1, 1) + dt.timedelta(hours=h) for h in range(8760)]
        return float(np.mean(self.series(year)))


def _clock(starts: list[dt.datetime]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    hour = np.array([t.hour + t.minute / 60 for t in starts], float)
    return hour, np.array([t.weekday() for t in starts]), np.array([t.month for t in starts])


def read_csv(path: Path) -> tuple[tuple[dt.datetime, ...], tuple[float, ...]]:
    """`time,price` rows (ISO times; the year is ignored, so one year's series prices any weather year)."""
    rows = []
    with path.open(newline="") as f:
        for r in csv.DictReader(f):
            rows.append((dt.datetime.fromisoformat(r["time"]).replace(year=2001), float(r["price"])))
    if not rows:
        raise ValueError(f"{path}: no `time,price` rows")
    rows.sort()
    return tuple(t for t, _ in rows), tuple(p for _, p in rows)


def load_tariff_file(value: dict, base: Path, where: str, errors: list[str]) -> Any:
    """`{ file = "x.toml" }`: the table in that file (relative to the spec, or a built-in tariff by bare name)."""
    from parallel_eplus.buildings.resources import tariff_file

    name = value["file"]
    path = (base / str(name)).expanduser()
    if not path.is_file():
        try:
            path = tariff_file(str(name))
        except FileNotFoundError as e:
            errors.append(f"{where}.file: {e}")
            return None
    try:
        table = tomllib.loads(path.read_text(encoding="utf-8"))
    except tomllib.TOMLDecodeError as e:
        errors.append(f"{where}.file: {path}: malformed TOML: {e}")
        return None
    if "csv" in table:  # a series beside the tariff file
        table["csv"] = str((path.parent / table["csv"]).resolve())
    return table


def check_tariff(value: Any, where: str, errors: list[str], electricity: bool) -> None:
    """Append every problem of one fuel's tariff value to `errors`."""
    if isinstance(value, (int, float)) and not isinstance(value, bool):
        if value < 0:
            errors.append(f"{where}: {value!r} is not a price per kWh (a number >= 0)")
        return
    if not isinstance(value, dict):
        errors.append(f'{where}: {value!r} is not a price per kWh or a table ({{ price = .., demand = [..] }}, '
                      '{ day = .., night = .. }, { csv = "prices.csv" } or { file = "tariff.toml" })')  # fmt: skip
        return
    unknown = set(value) - KEYS
    if unknown:
        errors.append(f"{where}: unknown key(s) {sorted(unknown)}; use {sorted(KEYS - {'file'})}")
    forms = [f for f in ENERGY_FORMS if f <= set(value)]
    if len(forms) != 1:
        errors.append(f"{where}: give the energy price once: price (with optional periods), day and night, or csv "
                      f"(got {sorted(set(value) & {'price', 'day', 'night', 'csv'}) or 'none'})")  # fmt: skip
    for key in ("price", "day", "night"):
        if key in value and not _price(value[key]):
            errors.append(f"{where}.{key}: {value[key]!r} is not a price (a number >= 0)")
    if "periods" in value and "price" not in value:
        errors.append(f"{where}.periods: needs price, the price where no period applies")
    if "day_hours" in value:
        _hours(value["day_hours"], f"{where}.day_hours", errors)
    for key in ("periods", "demand"):
        items = value.get(key, [])
        if not isinstance(items, list):
            errors.append(f"{where}.{key}: {items!r} is not a list of tables {{ price = .., hours = [a, b], ... }}")
            continue
        for i, t in enumerate(items):
            _window(t, f"{where}.{key}[{i}]", errors)
    if value.get("demand") and not electricity:
        errors.append(f"{where}.demand: demand charges apply to Electricity (the facility's electric demand)")


def _price(x: Any) -> bool:
    return isinstance(x, (int, float)) and not isinstance(x, bool) and x >= 0


def _hours(h: Any, where: str, errors: list[str]) -> None:
    if not (isinstance(h, list) and len(h) == 2 and all(_price(x) and x <= 24 for x in h) and h[0] != h[1]):
        errors.append(f"{where}: {h!r} is not [start, end] hours within 0-24 (start > end wraps past midnight)")


def _window(t: Any, where: str, errors: list[str]) -> None:
    if not isinstance(t, dict):
        errors.append(f"{where}: {t!r} is not a table {{ price = .., hours = [a, b], weekdays = [..], months = [..] }}")
        return
    unknown = set(t) - WINDOW_KEYS
    if unknown:
        errors.append(f"{where}: unknown key(s) {sorted(unknown)}; use {sorted(WINDOW_KEYS)}")
    if not _price(t.get("price")):
        errors.append(f"{where}.price: {t.get('price')!r} is not a price (a number >= 0)")
    hours = t.get("hours")
    for h in hours if isinstance(hours, list) and hours and isinstance(hours[0], list) else [hours] if hours else []:
        _hours(h, f"{where}.hours", errors)
    days = t.get("weekdays", [])
    if not isinstance(days, list) or any(d not in WEEKDAYS for d in days):
        errors.append(f"{where}.weekdays: {days!r} is not a list among {list(WEEKDAYS)}")
    months = t.get("months", [])
    if not isinstance(months, list) or any(not isinstance(m, int) or not 1 <= m <= 12 for m in months):
        errors.append(f"{where}.months: {months!r} is not a list of months 1-12")


@dataclass(frozen=True)
class PriceOutlook:
    """Prices of future steps for a planner: energy price per kWh, demand charges per kW in force, on-peak or not."""

    price: np.ndarray
    demand_rate: np.ndarray
    on_peak: np.ndarray


def price_outlook(building, starts, fuel: str = "Electricity") -> PriceOutlook:
    """The energy price (per kWh), the demand charges in force (per kW of the month's 15-minute peak) and whether an
    on-peak demand window is open, for steps starting at `starts` (datetimes; the year is the episode's), under the
    building's tariff for `fuel` (a Building or a BuildingSpec; an unnamed fuel at the placeholder price)."""
    spec = getattr(building, "spec", building)
    named = dict(spec.kpis.tariff)
    tariff = (Tariff.of(named[fuel], spec.path.parent) if fuel in named
              else Tariff(constant=DEFAULT_PRICES.get(fuel, 0.0)))  # fmt: skip
    rate, on_peak = tariff.demand_rates(starts)
    return PriceOutlook(tariff.series(starts), rate, on_peak)
