"""A weather forecast for the coming steps, from one interface with three sources: `WeatherSource.weather(now,
times)` gives the outdoor dry bulb (°C), relative humidity (%) and global horizontal radiation (W/m²) at `times` as
known at `now`.
- `PerfectForecast`: the weather file itself, interpolated between hours as EnergyPlus does (results that use it
  are an upper bound: say so);
- `ErroredForecast`: the file minus BOPTEST's AR(1) forecast errors (its levels below, Zabala et al.) on dry
  bulb and global horizontal radiation, redrawn each hour and growing with the lead time; BOPTEST models no
  humidity error, so relative humidity stays the file's;
- `GivenForecast`: a forecast supplied by the caller (a request to a served planner).
Numpy only at import: the served planner reads `WEATHER` here.
"""

from __future__ import annotations

import datetime as dt
import functools
import zlib
from pathlib import Path
from typing import Protocol

import numpy as np

WEATHER = ("outdoor_drybulb_c", "outdoor_rh_pct", "global_horizontal_w_m2")  # a forecast's variables, in order
WEATHER_UNITS = ("C", "%", "W/m2")
# BOPTEST's levels (forecast/forecast_uncertainty_params.json): dry bulb in K, global horizontal solar in W/m2.
TEMPERATURE_ERROR = {
    "low": {"F0": 0.0, "K0": 0.6, "F": 0.92, "K": 0.4, "mu": 0.0},
    "medium": {"F0": 0.15, "K0": 1.2, "F": 0.93, "K": 0.6, "mu": 0.0},
    "high": {"F0": -0.58, "K0": 1.5, "F": 0.95, "K": 0.7, "mu": -0.015},
}
SOLAR_ERROR = {
    "low": {"ag0": 4.44, "bg0": 57.42, "phi": 0.62, "ag": 1.86, "bg": 45.64},
    "medium": {"ag0": 15.02, "bg0": 122.6, "phi": 0.63, "ag": 4.44, "bg": 91.97},
    "high": {"ag0": 32.09, "bg0": 119.94, "phi": 0.67, "ag": 10.63, "bg": 87.44},
}
ERROR_LEVELS = tuple(TEMPERATURE_ERROR)
FORECASTS = ("perfect", *ERROR_LEVELS)


def ar1_temperature_error(n: int, level: str, rng: np.random.Generator) -> np.ndarray:
    p = TEMPERATURE_ERROR[level]
    e = np.empty(n)
    e[0] = rng.normal(p["F0"], p["K0"])
    for j in range(1, n):
        e[j] = rng.normal(p["F"] * e[j - 1] + p["mu"], p["K"])
    return e


def ar1_solar_error(n: int, level: str, rng: np.random.Generator) -> np.ndarray:
    p = SOLAR_ERROR[level]
    e = np.empty(n)
    e[0] = rng.laplace(p["ag0"], p["bg0"])
    for j in range(1, n):
        e[j] = rng.laplace(p["phi"] * e[j - 1] + p["ag"], p["bg"])
    return e


_COLUMNS = (6, 8, 13)  # EPW columns (0-based): dry bulb (C), relative humidity (%), global horizontal (Wh/m2)


@functools.lru_cache(maxsize=32)  # noisy runs read a file per episode
def _epw(path: Path) -> np.ndarray:
    """The hourly values of `_COLUMNS`, one row per hour of the year (8760)."""
    rows = []
    with open(path, encoding="latin-1") as f:
        for i, line in enumerate(f):
            if i < 8:
                continue
            parts = line.split(",")
            rows.append([float(parts[c]) for c in _COLUMNS])
    return np.array(rows)


def _hour_of_year(t: dt.datetime) -> float:
    return (t.timetuple().tm_yday - 1) * 24 + t.hour + t.minute / 60


class WeatherSource(Protocol):
    def weather(self, now: dt.datetime, times: list[dt.datetime]) -> np.ndarray:
        """[len(times), 3]: dry bulb (°C), relative humidity (%), global horizontal (W/m²) as known at `now`."""


class PerfectForecast:
    """The weather file's values at any time of its year (EnergyPlus's interpolation between hours)."""

    def __init__(self, path: Path):
        self.hourly = _epw(Path(path))
        n = len(self.hourly)  # value i of the file is the hour ending at i + 1; wrap at the year's end
        self._x = np.concatenate([[0.0], np.arange(1, n + 1)])
        self._table = np.concatenate([self.hourly[-1:], self.hourly])

    def truth(self, times: list[dt.datetime]) -> np.ndarray:
        hours = np.array([_hour_of_year(t) for t in times]) % len(self.hourly)
        return np.stack([np.interp(hours, self._x, self._table[:, j]) for j in range(3)], axis=1)

    def weather(self, now: dt.datetime, times: list[dt.datetime]) -> np.ndarray:
        return self.truth(times)


class ErroredForecast(PerfectForecast):
    """The file minus BOPTEST's AR(1) errors at `level`, drawn from (seed, the file, the hour of `now`): the same
    hour gets the same forecast, so an evaluation repeats."""

    def __init__(self, path: Path, level: str, seed: int = 0):
        super().__init__(path)
        if level not in ERROR_LEVELS:
            raise ValueError(f"forecast error {level!r}: one of {', '.join(ERROR_LEVELS)}")
        self.level, self.seed, self._file = level, seed, zlib.crc32(str(path).encode())

    def weather(self, now: dt.datetime, times: list[dt.datetime]) -> np.ndarray:
        truth = self.truth(times)
        hour = int(_hour_of_year(now))
        ahead = np.array([_hour_of_year(t) for t in times]) - hour  # hours from the top of `now`'s hour
        ahead = np.where(ahead < 0, ahead + len(self.hourly), ahead)
        rng = np.random.default_rng([self.seed, self._file, hour])
        n = int(np.ceil(ahead.max())) + 2
        grid = np.arange(n)
        out = truth.copy()
        out[:, 0] -= np.interp(ahead, grid, ar1_temperature_error(n, self.level, rng))
        solar = truth[:, 2] - np.interp(ahead, grid, ar1_solar_error(n, self.level, rng))
        out[:, 2] = np.clip(solar, 0.2 * truth[:, 2], 2.0 * truth[:, 2])  # BOPTEST's bounds (none at night)
        return out


class GivenForecast:
    """A caller's forecast: [horizon, 3] values at the ends of the coming steps, in `times`' order."""

    def __init__(self, values: np.ndarray):
        self.values = np.asarray(values, float)

    def weather(self, now: dt.datetime, times: list[dt.datetime]) -> np.ndarray:
        return self.values[: len(times)]
