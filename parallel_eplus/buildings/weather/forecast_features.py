"""Forecasts as observations: the coming hours of an EPW column, read from the episode's own weather file.

The learner's side computes them (the env knows the episode's time and its EPW, the perturbed one when the
weather is noisy: a forecast is never better than the weather the simulation runs). Entry k of a forecast is the
column at t + k x stride, t the observation's time, interpolated linearly between the file's records (record i
of an hourly file holds the value at the end of hour i, as EnergyPlus reads it); past the run period's end the
last value within it repeats.

Optional forecast error as BOPTEST adds it (its `forecast_uncertainty_params.json`, Zabala et al.): an AR(1)
error on hourly points across the horizon, `e[0] ~ N(F0, K0)`, `e[j+1] ~ N(F e[j] + mu, K)`, subtracted from the
truth, redrawn each hour and interpolated between hours; solar columns get BOPTEST's Laplace AR(1)
(`e[0] ~ Laplace(ag0, bg0)`, `e[j+1] ~ Laplace(phi e[j] + ag, bg)`), clipped to 0.2-2 x the truth.
"""

from __future__ import annotations

import datetime as dt
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from parallel_eplus.buildings.weather.epw import column_index, read_epw, records_per_hour
from parallel_eplus.buildings.weather.forecast import ERROR_LEVELS, ar1_solar_error, ar1_temperature_error

TEMPERATURES = ("drybulb", "dewpoint")
SOLAR = ("glohorrad", "dirnorrad", "difhorrad")
OUTDOOR = "outdoor_forecast"  # `train --forecast N`'s observation name


@dataclass(frozen=True)
class ForecastSpec:
    """`count` values of an EPW column, `stride` apart (hours, or control steps with `in_steps`)."""

    name: str
    column: str = "drybulb"
    count: int = 24
    stride: float = 1.0
    in_steps: bool = False
    error: str | None = None  # None, or BOPTEST's "low", "medium", "high"
    low: float = -70.0
    high: float = 70.0

    def __post_init__(self):
        column_index(self.column)
        if self.count < 1 or self.stride <= 0:
            raise ValueError(f"forecast {self.name}: count must be >= 1 and stride > 0")
        if self.error is not None and (self.error not in ERROR_LEVELS or self.column not in TEMPERATURES + SOLAR):
            raise ValueError(
                f"forecast {self.name}: error {self.error!r} needs one of {', '.join(ERROR_LEVELS)} on a temperature "
                f"({', '.join(TEMPERATURES)}) or solar column ({', '.join(SOLAR)})"
            )

    @property
    def names(self) -> tuple[str, ...]:
        """The observation elements it adds: `<name>_1` ... `<name>_<count>`."""
        return tuple(f"{self.name}_{k}" for k in range(1, self.count + 1))


def outdoor_forecast(hours: int, error: str | None = None) -> ForecastSpec:
    """`train --forecast N`: the outdoor dry bulb over the next N hours, hourly."""
    return ForecastSpec(OUTDOOR, "drybulb", hours, 1.0, False, error)


class Forecaster:
    """One episode's forecasts: built from its weather file when it starts, asked at each observation."""

    def __init__(self, specs: tuple[ForecastSpec, ...], epw: Path, run_days: int, steps_per_hour: int, seed: int,
                 start_day: int = 1):  # fmt: skip
        """`start_day`, `run_days`: the run period (day of the year it starts on, its length), where forecasts end."""
        header, data = read_epw(epw)
        rph = records_per_hour(header)
        self.specs = specs
        self.times = np.arange(1, len(data) + 1) / rph  # hours since Jan 1 00:00 at each record's end
        self.columns = {s.column: data[s.column].to_numpy(float) for s in specs}
        self.end_h = min((start_day - 1 + run_days) * 24.0, float(self.times[-1]))  # the run's last hour
        self.steps_per_hour = steps_per_hour
        self.rng = np.random.default_rng(seed)
        self._origin: dt.datetime | None = None
        self._errors: dict[int, tuple[float, np.ndarray]] = {}  # spec -> (the hour drawn at, hourly errors)

    def __call__(self, t: dt.datetime) -> tuple[float, ...]:
        """Every spec's values at the observation taken at `t`, in order."""
        if self._origin is None:
            self._origin = dt.datetime(t.year, 1, 1)
        now = (t - self._origin).total_seconds() / 3600.0
        out: list[float] = []
        for i, s in enumerate(self.specs):
            stride_h = s.stride / self.steps_per_hour if s.in_steps else s.stride
            ahead = np.arange(1, s.count + 1) * stride_h
            when = np.minimum(now + ahead, self.end_h)
            values = np.interp(when, self.times, self.columns[s.column])
            if s.error is not None:
                values = self._with_error(i, s, now, ahead, values)
            out += values.tolist()
        return tuple(out)

    def _with_error(self, i: int, s: ForecastSpec, now: float, ahead: np.ndarray, truth: np.ndarray) -> np.ndarray:
        hour = float(np.floor(now))
        drawn = self._errors.get(i)
        if drawn is None or drawn[0] != hour:  # BOPTEST redraws the error when the hour changes
            n = int(np.ceil(ahead[-1] + (now - hour))) + 2
            draw = ar1_temperature_error if s.column in TEMPERATURES else ar1_solar_error
            drawn = self._errors[i] = (hour, draw(n, s.error, self.rng))
        error = np.interp(now - hour + ahead, np.arange(len(drawn[1])), drawn[1])
        forecast = truth - error
        if s.column in SOLAR:
            forecast = np.clip(forecast, 0.2 * truth, 2.0 * truth)  # BOPTEST's bounds (none at night)
        return forecast
