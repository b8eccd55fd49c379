"""The model's exogenous inputs from a weather forecast and the clock: one definition for training, `evaluate` and
the served planner.

A forecast is the outdoor dry bulb (°C), relative humidity (%) and global horizontal radiation (W/m²) at the end
of each coming step, whoever made it (buildings/weather/forecast.py): the weather file, the file with BOPTEST's
forecast errors, or a building's forecast service in a request to `serve`. To these the clock adds hour and
weekday (sine/cosine) and, for a model with the data center's IT-load schedule, its value: the operator knows it.
No torch, no EnergyPlus: the server imports this.
"""

from __future__ import annotations

import datetime as dt

import numpy as np

from parallel_eplus.buildings.clock import time_features

WEATHER_SCALE = np.array([1.0, 0.01, 0.001])  # to numbers of order one
EXOGENOUS = ("outdoor_drybulb_c", "outdoor_rh", "global_horizontal_kw_m2", "hour_sin", "hour_cos", "weekday_sin",
             "weekday_cos")  # fmt: skip
Schedule = tuple[tuple[float, float], ...]  # (until hour, value): a daily schedule


def width(schedule: Schedule | None) -> int:
    return len(EXOGENOUS) + (schedule is not None)


def schedule_value(t: dt.datetime, schedule: Schedule) -> float:
    hour = t.hour + t.minute / 60
    return next((v for until, v in schedule if hour < until), schedule[-1][1])


def exogenous(weather: np.ndarray, times: list[dt.datetime], schedule: Schedule | None) -> np.ndarray:
    """[len(times), width]: the model's exogenous inputs at the end of each step, from `weather` [T, 3] (physical
    units, `WEATHER`'s order) at those times."""
    parts = [np.asarray(weather, float) * WEATHER_SCALE, np.array([time_features(t) for t in times])]
    if schedule is not None:  # the load during the step that ends at t
        parts.append(np.array([[schedule_value(t - dt.timedelta(minutes=1), schedule)] for t in times]))
    return np.concatenate(parts, axis=1).astype(np.float32)


def with_occupancy(exo: np.ndarray, occupied: np.ndarray) -> np.ndarray:
    """`exo` [..., T, X] with whether the building is occupied at each step's end [..., T] as one more column
    (`occupancy_input`)."""
    return np.concatenate([exo, np.asarray(occupied, np.float32)[..., None]], axis=-1).astype(np.float32)


def step_times(now: dt.datetime, step_minutes: float, horizon: int) -> list[dt.datetime]:
    """The ends of the `horizon` steps that start at `now`."""
    return [now + dt.timedelta(minutes=step_minutes * (h + 1)) for h in range(horizon)]
