"""`PUT /forecast`: the coming values of the weather file (buildings/weather/forecast.py: as EnergyPlus interpolates
it, less BOPTEST's AR(1) errors under `temperature_uncertainty` / `solar_uncertainty`) and of the price scenarios'
tariffs, at `now`, `now + interval`, ... up to `now + horizon`.
"""

from __future__ import annotations

import datetime as dt
from pathlib import Path

import numpy as np

from parallel_eplus.buildings.weather.forecast import ErroredForecast, PerfectForecast
from parallel_eplus.deploy.boptest.points import EMISSIONS_POINT, KELVIN, PRICE_POINTS

MAX_UNCERTAIN_HORIZON_S = 48 * 3600  # BOPTEST's error models hold for 48 hours
MAX_POINTS = 100_000  # values per point in one answer


class ForecastError(ValueError):
    """A forecast query BOPTEST would refuse (400), with the reason."""


def forecast_times(now_s: float, horizon: float, interval: float) -> np.ndarray:
    """BOPTEST's forecast times (seconds since January 1): `now` to `now + horizon` every `interval`."""
    if not horizon >= 0:
        raise ForecastError(f"horizon is {horizon}: it must be a number of seconds, 0 or more")
    if not interval > 0:
        raise ForecastError(f"interval is {interval}: it must be a positive number of seconds")
    n = int(np.floor(horizon / interval + 1e-9)) + 1
    if n > MAX_POINTS:
        raise ForecastError(f"horizon/interval asks for {n} values per point; at most {MAX_POINTS}")
    return now_s + interval * np.arange(n)


def weather_forecast(epw: Path, year: int, times: np.ndarray, scenario, now: dt.datetime) -> dict[str, list]:
    """TDryBul (K), relHum (0-1), HGloHor (W/m²) at `times` as known at `now`."""
    if (scenario.temperature_uncertainty or scenario.solar_uncertainty) and times[-1] - times[0] > \
            MAX_UNCERTAIN_HORIZON_S:  # fmt: skip
        raise ForecastError(f"horizon {times[-1] - times[0]:.0f} s: at most {MAX_UNCERTAIN_HORIZON_S} s (48 h) under a "
                            "temperature or solar uncertainty scenario, as BOPTEST allows")  # fmt: skip
    start = dt.datetime(year, 1, 1)
    at = [start + dt.timedelta(seconds=float(s)) for s in times]
    values = PerfectForecast(epw).weather(now, at)
    seed = scenario.seed or 0
    if scenario.temperature_uncertainty:
        values[:, 0] = ErroredForecast(epw, scenario.temperature_uncertainty, seed).weather(now, at)[:, 0]
    if scenario.solar_uncertainty:
        values[:, 2] = ErroredForecast(epw, scenario.solar_uncertainty, seed).weather(now, at)[:, 2]
    return {"TDryBul": (values[:, 0] + KELVIN).tolist(), "relHum": (values[:, 1] / 100).tolist(),
            "HGloHor": values[:, 2].tolist()}  # fmt: skip


def price_forecast(tariffs: dict, factor: float, year: int, times: np.ndarray) -> dict[str, list]:
    """Each price scenario's electricity price at `times` (the price of a step starting then) and the emission
    factor."""
    start = dt.datetime(year, 1, 1)
    at = [start + dt.timedelta(seconds=float(s)) for s in times]
    out = {PRICE_POINTS[s]: t.series(at).tolist() for s, t in tariffs.items()}
    out[EMISSIONS_POINT] = [factor] * len(times)
    return out
