"""One frame from EnergyPlus as the agent sees it: the observed sensors clipped to their bounds, then the opt-in
features (time, the IT-load schedule, weather forecasts), and every sensor by name in `info`.

Per step, Python floats are cheaper than numpy scalars and small-array ops (docs/speed.md): the bounds are kept
as tuples of floats for the check, and numpy is used only for the observation itself.
"""

from __future__ import annotations

import numpy as np

from parallel_eplus.buildings.datacenter import schedule_features, time_features
from parallel_eplus.buildings.weather.forecast_features import Forecaster
from parallel_eplus.engine.pipes import frames
from parallel_eplus.engine.setup import WorkerSetup


class Observer:
    """(observation, info, sensor values) from a frame's values; `width` is the frame's expected length."""

    def __init__(self, setup: WorkerSetup):
        self.sensor_names = setup.building.sensor_names
        self.width = frames.TIME_FIELDS + len(self.sensor_names)
        self.obs_low, self.obs_high = setup.obs_low, setup.obs_high
        self._lows, self._highs = (tuple(b.tolist()) for b in (setup.obs_low, setup.obs_high))  # float32, as floats
        self._observed = setup.observed
        self._hidden = setup.building.hidden  # thermostat schedules, HVAC meters: in `info`, not the observation
        self._time = setup.config.time_features
        self._schedule = setup.schedule

    def __call__(self, values: np.ndarray, weather: str, forecaster: Forecaster | None):
        fields = values.tolist()
        sensed = fields[frames.TIME_FIELDS :]
        info = dict(zip(self.sensor_names, sensed, strict=True))
        info["time"] = frames.frame_time(fields)
        info["weather"] = weather
        if self._hidden:
            raw = values[frames.TIME_FIELDS : frames.TIME_FIELDS + self._observed]
            observed = sensed[: self._observed]
        else:
            raw, observed = values[frames.TIME_FIELDS :], sensed
        obs = raw.astype(np.float32)
        for lo, v, hi in zip(self._lows, observed, self._highs, strict=True):
            if not lo <= v <= hi:  # (NaN too)
                info["raw_observation"] = raw.copy()
                obs = np.clip(obs, self.obs_low, self.obs_high)
                break
        if self._time or self._schedule or forecaster:
            extra = time_features(info["time"]) if self._time else ()
            if self._schedule:
                extra += schedule_features(info["time"], self._schedule)
            if forecaster:  # the spec's forecasts, then --forecast's
                extra += forecaster(info["time"])
            obs = np.concatenate([obs, np.array(extra, np.float32)])
        return obs, info, sensed
