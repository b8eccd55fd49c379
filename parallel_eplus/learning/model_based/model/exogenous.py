"""What the model is told about the weather: the year as it happened (its data) and a forecast (its plans).

The model learns from the weather that happened: the episode's own .epw file (the perturbed year, with weather
noise: info["weather_file"]), interpolated between hours as EnergyPlus does. The planner reads the coming hours
through buildings/weather/forecast.py's one interface (the file, the file with BOPTEST's forecast errors, or a
caller's forecast); features.py turns them, with the clock and the model's schedule, into the model's inputs.
"""

from __future__ import annotations

import datetime as dt
import functools
from pathlib import Path

import numpy as np

from parallel_eplus.buildings.building import load_building, weather_path
from parallel_eplus.buildings.datacenter import IT_SCHEDULE, it_load_schedule
from parallel_eplus.buildings.weather.forecast import ErroredForecast, PerfectForecast, WeatherSource
from parallel_eplus.learning.model_based.runtime.features import Schedule, exogenous, width


@functools.cache
def model_schedule(building: str | None) -> Schedule | None:
    """The model's IT-load schedule where it has one (the data centers), else None."""
    try:
        return it_load_schedule(load_building(building).control().idf, IT_SCHEDULE)
    except (ValueError, OSError):
        return None


class Forecast:
    """One weather's exogenous inputs: `at(times)` as they happened (the model's data), `ahead(now, times)` as the
    planner is told them at `now` (the source's forecast)."""

    def __init__(self, building: str | None, weather: str, error: str | None = None, seed: int = 0):
        path = weather_path(building, weather)
        self.file = PerfectForecast(path)
        self.source: WeatherSource = self.file if error in (None, "perfect") else ErroredForecast(path, error, seed)
        self.schedule = model_schedule(building)

    @property
    def width(self) -> int:
        return width(self.schedule)

    def at(self, times: list[dt.datetime]) -> np.ndarray:
        return exogenous(self.file.truth(times), times, self.schedule)

    def ahead(self, now: dt.datetime, times: list[dt.datetime]) -> np.ndarray:
        return exogenous(self.source.weather(now, times), times, self.schedule)


class Forecasts:
    """One `Forecast` per weather (or per episode's perturbed file), made on first use; `error`: the planner's
    forecast (None or "perfect": the file; BOPTEST's "low", "medium", "high": with its errors)."""

    _FILES = 16  # perturbed years kept: a few per worker

    def __init__(self, building: str | None, error: str | None = None, seed: int = 0):
        self.building, self.error, self.seed = building, error, seed
        self._by_weather: dict[str, Forecast] = {}
        self._by_file: dict[str, Forecast] = {}

    def __call__(self, weather: str) -> Forecast:
        if weather not in self._by_weather:
            self._by_weather[weather] = Forecast(self.building, weather, self.error, self.seed)
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
        self._by_file[file] = Forecast(self.building, file, self.error, self.seed)
        return self._by_file[file]
