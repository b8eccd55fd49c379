"""BOPTEST's scenarios on a building: `electricity_price` (constant and dynamic: BOPTEST's Chicago tariffs shipped in
buildings/tariffs/; highly dynamic: the spec's own electricity price series, where it gives one), `time_period`
(BOPTEST's four test periods as `evaluate --scenario` finds them: evaluation/scenarios.py), `temperature_uncertainty`
and `solar_uncertainty` (BOPTEST's forecast-error levels: buildings/weather/forecast.py) and `seed`.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field
from pathlib import Path

from parallel_eplus.buildings.pricing.tariff import Tariff, load_tariff_file
from parallel_eplus.buildings.weather.forecast import ERROR_LEVELS

log = logging.getLogger(__name__)

PRICES = ("constant", "dynamic", "highly_dynamic")
PRICE_FILES = {"constant": "boptest-constant.toml", "dynamic": "boptest-dynamic.toml"}
TIME_PERIODS = ("peak_heat_day", "typical_heat_day", "peak_cool_day", "typical_cool_day")
KEYS = ("electricity_price", "time_period", "temperature_uncertainty", "solar_uncertainty", "seed")


class ScenarioError(ValueError):
    """A scenario value BOPTEST would refuse (400), with the reason."""


def price_tariffs(building) -> dict[str, Tariff]:
    """The electricity tariff of each price scenario this building offers: BOPTEST's constant and dynamic ones, and
    as highly dynamic the spec's own price series (`[kpis] tariff.Electricity = { csv = ... }`) where it has one."""
    out = {}
    for scenario, name in PRICE_FILES.items():
        errors: list[str] = []
        table = load_tariff_file({"file": name}, building.spec.path.parent, f"electricity_price {scenario}", errors)
        if errors:  # pragma: no cover - the files ship with the package
            raise FileNotFoundError("; ".join(errors))
        out[scenario] = Tariff.of(table, building.spec.path.parent)
    kpis = building.comfort.kpis
    own = kpis.tariffs.get("Electricity") if kpis is not None else None
    if own is not None and own.times:
        out["highly_dynamic"] = own
    return out


@dataclass
class Scenario:
    """The test's scenario as BOPTEST's `GET /scenario` reports it."""

    electricity_price: str = "constant"
    time_period: str | None = None
    temperature_uncertainty: str | None = None
    solar_uncertainty: str | None = None
    seed: int | None = None
    offered: tuple[str, ...] = field(default=("constant", "dynamic"), repr=False)  # the price scenarios available

    def as_dict(self) -> dict:
        return {k: getattr(self, k) for k in KEYS}

    def update(self, given: dict) -> dict:
        """Checks every value of `given` (a PUT /scenario body) before changing any; returns what changed, as
        BOPTEST's payload has it (None where a key was not set). Keys BOPTEST does not know are refused."""
        unknown = sorted(set(given) - set(KEYS))
        if unknown:
            raise ScenarioError(f"unknown scenario key(s) {unknown}: use {', '.join(KEYS)}")
        price = given.get("electricity_price")
        if price is not None:
            if price not in PRICES:
                raise ScenarioError(f"electricity_price is {price!r}, but should be one of {', '.join(PRICES)}")
            if price not in self.offered:
                raise ScenarioError(
                    f"electricity_price {price!r}: this building has no highly dynamic price series (BOPTEST's is "
                    "ComEd's 2019 day-ahead prices, not shipped); give the spec one as [kpis] tariff.Electricity = "
                    '{ csv = "prices.csv" } (docs/kpis.md), or use constant or dynamic'
                )
        period = given.get("time_period")
        if period is not None and period not in TIME_PERIODS:
            raise ScenarioError(f"time_period is {period!r}, but should be one of {', '.join(TIME_PERIODS)}")
        levels = {}
        for key in ("temperature_uncertainty", "solar_uncertainty"):
            level = given.get(key)
            if level is not None and level not in ("none", *ERROR_LEVELS):
                raise ScenarioError(f"{key} is {level!r}, but should be none, {', '.join(ERROR_LEVELS)}")
            levels[key] = None if level in (None, "none") else level
        seed = given.get("seed")
        if seed is not None and (isinstance(seed, bool) or not isinstance(seed, int) or seed < 0):
            raise ScenarioError(f"seed is {seed!r}, but should be a non-negative integer")
        changed = dict.fromkeys(KEYS)
        if price is not None:
            self.electricity_price = changed["electricity_price"] = price
        for key, level in levels.items():  # as BOPTEST: a level not given is reset to none
            setattr(self, key, level)
            changed[key] = level
        self.seed = changed["seed"] = seed
        if period is not None:
            self.time_period = period
        return changed


def test_period(building, weather: str, time_period: str, cache: Path):
    """The period `evaluate --scenario` scores for `time_period` (BOPTEST's name, `peak_heat_day`) on `weather`:
    found from a year of the building's own controls the first time (minutes), then read from `cache`."""
    from parallel_eplus.buildings.weather.files import weather_label
    from parallel_eplus.evaluation.scenarios import find_periods

    scenario = time_period.removesuffix("_day")
    try:
        return find_periods(scenario, [weather], building, cache, workers=1, progress=False)[weather_label(weather)]
    except ValueError as e:
        raise ScenarioError(f"time_period {time_period!r}: {e}") from None
