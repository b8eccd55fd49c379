"""What the model is told about the future: the weather file (a perfect forecast), the clock and the schedule.

The planner reads the future outdoor conditions from the episode's own .epw file (the perturbed year, with
weather noise: info["weather_file"]): a perfect forecast, which a deployed controller would replace by a weather
service's. EnergyPlus interpolates the hourly file between hours; so does `Forecast.at`. The clock gives hour and
weekday (sine/cosine); a model with the data center's IT-load schedule adds its value (the operator knows it).
"""

from __future__ import annotations

import datetime as dt
import functools
from pathlib import Path

import numpy as np

from parallel_eplus.buildings.building import load_building
from parallel_eplus.buildings.model import IT_SCHEDULE, it_load_schedule, time_features
from parallel_eplus.buildings.weather import resolve_weather

# EPW columns (0-based): dry bulb (C), relative humidity (%), global horizontal radiation (Wh/m2)
_COLUMNS = (6, 8, 13)
_SCALE = np.array([1.0, 0.01, 0.001])  # to numbers of order one
EXOGENOUS = ("outdoor_drybulb_c", "outdoor_rh", "global_horizontal_kw_m2", "hour_sin", "hour_cos", "weekday_sin",
             "weekday_cos")  # fmt: skip


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
    return np.array(rows) * _SCALE


def weather_path(building: str | None, weather: str) -> Path:
    """The .epw of a weather as the spec names it (its short names, the paper's codes, or a path)."""
    named = load_building(building).spec.weathers
    return Path(named.get(weather) or resolve_weather(weather))


@functools.cache
def _schedule(building: str | None) -> tuple[tuple[float, float], ...] | None:
    try:
        return it_load_schedule(load_building(building).control().idf, IT_SCHEDULE)
    except (ValueError, OSError):
        return None


class Forecast:
    """Exogenous inputs at any time of one weather's year: `at(times)` -> [len(times), width]."""

    def __init__(self, building: str | None, weather: str):
        self.hourly = _epw(weather_path(building, weather))
        self.schedule = _schedule(building)

    @property
    def width(self) -> int:
        return len(EXOGENOUS) + (self.schedule is not None)

    def at(self, times: list[dt.datetime]) -> np.ndarray:
        hours = np.array([(t.timetuple().tm_yday - 1) * 24 + t.hour + t.minute / 60 for t in times])
        n = len(self.hourly)
        # value i of the file is the hour ending at i + 1; wrap at the year's end
        x = np.concatenate([[0.0], np.arange(1, n + 1)])
        table = np.concatenate([self.hourly[-1:], self.hourly])
        weather = np.stack([np.interp(hours % n, x, table[:, j]) for j in range(table.shape[1])], axis=1)
        clock = np.array([time_features(t) for t in times])
        parts = [weather, clock]
        if self.schedule is not None:
            # the load during the step that ends at t
            parts.append(np.array([[self._load(t - dt.timedelta(minutes=1))] for t in times]))
        return np.concatenate(parts, axis=1).astype(np.float32)

    def _load(self, t: dt.datetime) -> float:
        hour = t.hour + t.minute / 60
        return next((v for until, v in self.schedule if hour < until), self.schedule[-1][1])


class Forecasts:
    """One `Forecast` per weather (or per episode's perturbed file), made on first use."""

    _FILES = 16  # perturbed years kept: a few per worker

    def __init__(self, building: str | None):
        self.building = building
        self._by_weather: dict[str, Forecast] = {}
        self._by_file: dict[str, Forecast] = {}

    def __call__(self, weather: str) -> Forecast:
        if weather not in self._by_weather:
            self._by_weather[weather] = Forecast(self.building, weather)
        return self._by_weather[weather]

    def of(self, info: dict) -> Forecast:
        """The weather a step's episode runs: its perturbed file where it has one (weather noise) and this process
        can read it (a Ray worker on another machine keeps its files: the named weather then, a forecast with
        error), else its weather."""
        file = info.get("weather_file")
        if file in self._by_file:
            return self._by_file[file]
        if file is None or not Path(file).is_file():
            return self(info["weather"])
        if len(self._by_file) >= self._FILES:
            self._by_file.pop(next(iter(self._by_file)))
        self._by_file[file] = Forecast(self.building, file)
        return self._by_file[file]
