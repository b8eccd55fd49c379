"""One BOPTEST test: an EnergyPlus episode of a building (engine/simulation.py), started by `initialize` and stepped
by `advance`, one control step (`step`, a whole number of the model's timesteps) at a time.

The episode runs the building's own controls under its actions' actuators (`SimulationConfig.relinquish`): an
input not activated is NaN on its way to EnergyPlus, which leaves that actuator to the model's own setpoint
managers and schedules for the step, as BOPTEST's overwrite blocks leave its test cases' baseline controllers in
charge. The warm-up runs that way too, as BOPTEST's does. Every method returns (message, payload) or raises
`TestError` with the HTTP status BOPTEST answers and the reason; payloads are plain data, so a test can live in a
Ray actor (remote.py).
"""

from __future__ import annotations

import copy
import datetime as dt
import logging
import math
import time
from pathlib import Path

from parallel_eplus.buildings.building import load_building, weather_path
from parallel_eplus.buildings.scaling import normalize
from parallel_eplus.buildings.scoring.kpis import floor_area
from parallel_eplus.deploy.boptest.forecast import ForecastError, price_forecast, weather_forecast
from parallel_eplus.deploy.boptest.kpi import Totals, core_kpis, kpi_payload, scenario_comfort
from parallel_eplus.deploy.boptest.points import PRICE_POINTS, Points, activation
from parallel_eplus.deploy.boptest.scenario import Scenario, ScenarioError, price_tariffs, test_period
from parallel_eplus.engine.config import SimulationConfig
from parallel_eplus.errors import EnergyPlusError

log = logging.getLogger(__name__)

YEAR_S = 365 * 86400
DAY_S = 86400
PERIOD_S = 14 * DAY_S  # a time_period scenario's length


class TestError(Exception):
    """A request this test refuses (4xx) or could not do (5xx), with BOPTEST's status and the reason."""

    def __init__(self, status: int, message: str):
        super().__init__(message)
        self.status, self.message = status, message

    def __reduce__(self):  # raised in a Ray actor (remote.py), rebuilt whole on the server's side
        return TestError, (self.status, self.message)


def number(value, name: str) -> float:
    """A finite number from a JSON value (a number, or a string holding one, as BOPTEST accepts); else 400."""
    try:
        if isinstance(value, bool):
            raise ValueError
        x = float(value)
    except (TypeError, ValueError):
        raise TestError(400, f"{name} is {value!r}: it must be a number") from None
    if not math.isfinite(x):
        raise TestError(400, f"{name} is {value!r}: it must be a finite number")
    return x


def _flag(value, name: str) -> int:
    if isinstance(value, str) and value.lower() in ("true", "false"):
        return int(value.lower() == "true")
    x = number(value, name)
    if x not in (0.0, 1.0):
        raise TestError(400, f"{name} is {value!r}: an activation is 1 (overwrite) or 0 (the building's own control)")
    return int(x)


class BoptestTest:
    """One test of a test case (a building spec on one weather)."""

    __test__ = False  # not a pytest class

    def __init__(self, testcase: str, spec: str | Path, weather: str | None = None, cache: Path | None = None):
        self.testcase = testcase
        try:
            self.building = b = load_building(spec)
        except (OSError, ValueError) as e:  # a spec of --specs that does not load (SpecError is a ValueError)
            raise TestError(500, f"test case {testcase!r}: its spec {spec} does not load: {e}") from None
        self.weather = weather or next(iter(b.spec.weathers), "CA")
        try:
            self.epw = weather_path(b, self.weather)
        except (FileNotFoundError, ValueError) as e:
            raise TestError(400, f"weather {self.weather!r}: {e}") from None
        if not self.epw.is_file():
            raise TestError(400, f"weather {self.weather!r}: {self.epw} not found")
        self.tariffs = price_tariffs(b)
        self.points = Points.of(b, {PRICE_POINTS[s]: s for s in self.tariffs})
        self.scenario = Scenario(offered=tuple(self.tariffs))
        self.cache = cache or Path.home() / ".cache" / "parallel-eplus" / "boptest"
        self.dt = DAY_S // b.steps_per_day  # the model's timestep, s
        self.step_s = self.dt
        self.sim = None
        self.year = 2017
        self.now_s = 0.0
        self.start_s = self.kpi_s = 0.0
        self.end_s = float(YEAR_S)
        self.ended = False
        self.state: dict = {}
        self.results: dict[str, list] = {}
        self.time_ratios: list[float] = []
        self._tic: float | None = None
        self._ratio_sum = 0.0  # of time_ratios, kept as they come
        # the KPIs, incremental: the episode's step records, the first row they score, the rows folded so far
        # into `_totals` (made for one electricity price: a new price starts them afresh)
        self._recorder = None
        self._kpi_row = self._folded = 0
        self._totals: Totals | None = None
        self._totals_price: str | None = None
        self._area: float | None = None
        self._inputs = {p.name: i for i, p in enumerate(self.points.inputs)}
        self._activations = {activation(p.name): i for i, p in enumerate(self.points.inputs)}
        factor = b.comfort.kpis.factors.get("Electricity") if b.comfort.kpis is not None else None
        self.emission_factor = 0.37 if factor is None else factor

    # -- metadata ---------------------------------------------------------------------------------
    def name(self):
        return "Queried the name of the test case successfully.", {"name": self.testcase}

    def inputs(self):
        return "Queried the inputs successfully.", self.points.input_meta()

    def measurements(self):
        return "Queried the measurements successfully.", self.points.measurement_meta()

    def forecast_points(self):
        return "Queried the forecast points and their meta-data successfully.", self.points.forecast_meta()

    def get_step(self):
        return "Queried the control step successfully.", self.step_s

    def set_step(self, step):
        s = number(step, "step")
        k = s / self.dt
        if s <= 0 or abs(k - round(k)) > 1e-9:
            raise TestError(400, f"step {step!r} s: the control step must be a positive multiple of the model's "
                                 f"timestep, {self.dt} s (EnergyPlus steps the building in whole timesteps): "
                                 f"{self.dt}, {2 * self.dt}, {3 * self.dt}, ...")  # fmt: skip
        self.step_s = float(s)
        return "Control step set successfully.", {"step": self.step_s}

    def get_scenario(self):
        return "Queried the test case scenario successfully.", self.scenario.as_dict()

    # -- the episode ------------------------------------------------------------------------------
    def initialize(self, start_time, warmup_period, end_time: float | None = None, weekday: str | None = None):
        start, warmup = number(start_time, "start_time"), number(warmup_period, "warmup_period")
        if start < 0 or warmup < 0:
            which = "start_time" if start < 0 else "warmup_period"
            raise TestError(400, f"{which} is {start if start < 0 else warmup}: it must not be negative")
        if start >= YEAR_S:
            raise TestError(400, f"start_time {start:.0f} s is past the weather year's end ({YEAR_S} s)")
        aligned = math.ceil(start / self.dt - 1e-9) * self.dt
        end = float(YEAR_S if end_time is None else min(end_time, YEAR_S))
        first_day = int(max(aligned - warmup, 0) // DAY_S)  # 0-based: the run period begins on a whole day
        run_days = max(1, math.ceil(end / DAY_S - 1e-9) - first_day)
        self.close()
        config = SimulationConfig(
            weather=self.weather, building=str(self.building.spec.path), run_days=run_days,
            start_day=first_day + 1, start_weekday=weekday, relinquish=True, native_bridge=False,
            prepare_next=False, fork_episodes=False, keep_episodes=1,
            initial_action=(math.nan,) * len(self.building.actions),  # warm-up under the building's own controls
        )  # fmt: skip
        from parallel_eplus.engine.simulation import Simulation

        self.sim = Simulation(config, building=self.building)
        self.results, self.time_ratios, self._tic, self._area = {}, [], None, None
        self.ended, self.end_s = False, end
        try:
            obs, info = self.sim.start()
            self._recorder = self.sim.records  # kept: the episode's end writes them out and lets the sim's go
            self.year = info["time"].year
            released = [math.nan] * len(self.points.inputs)
            self._observe(info, [None] * len(released))
            while self.now_s < aligned - 1e-6 and not self.ended:
                self._step(released, [None] * len(released))
        except EnergyPlusError as e:
            self.close()
            raise TestError(500, f"Failed to initialize the test: {e}") from None
        self.start_s = self.kpi_s = aligned
        self._restart_kpis()
        note = "" if aligned == start else f" (start_time {start:g} s rounded up to the model's timestep, {self.dt} s)"
        message = f"Test simulation initialized successfully to {aligned:g}s with warmup period of {warmup:g}s{note}."
        return message, self.state

    def advance(self, u: dict):
        if not isinstance(u, dict):
            raise TestError(400, "the body must be a JSON object of inputs: {\"<name>_u\": value, "
                                 "\"<name>_activate\": 1}")  # fmt: skip
        values, active, alerts = self._parse(u)
        if self.sim is None:
            self.initialize(0, 0)
        if self.ended or self.now_s >= self.end_s:
            return "End of test case scenario time period reached.", {}
        if self._tic is not None:
            ratio = (time.monotonic() - self._tic) / self.step_s
            self.time_ratios.append(ratio)
            self._ratio_sum += ratio
        action, applied = [], []
        for p, v, on in zip(self.points.inputs, values, active, strict=True):
            a = self.building.actions[self._inputs[p.name]]
            physical = p.from_si(v) if on else math.nan
            action.append(normalize(physical, a.low, a.high) if on else math.nan)
            applied.append(v if on else None)
        begin = self.now_s
        try:
            for _ in range(round(self.step_s / self.dt)):
                self._step(action, applied)
                if self.ended or self.now_s >= self.end_s:
                    break
        except EnergyPlusError as e:
            self.close()
            raise TestError(500, f"Failed to advance simulation: {e}") from None
        self._tic = time.monotonic()
        message = "; ".join(alerts) or f"Advanced simulation successfully from {begin:g}s to {self.now_s:g}s."
        return message, self.state

    def _parse(self, u: dict) -> tuple[list[float], list[bool], list[str]]:
        """Each input's value (SI, saturated to its limits as BOPTEST does, with an alert) and activation."""
        n = len(self.points.inputs)
        values, active, alerts = [math.nan] * n, [False] * n, []
        known = sorted([*self._inputs, *self._activations])
        for key, value in u.items():
            if key not in self._inputs and key not in self._activations:
                raise TestError(400, f"Unexpected input variable: {key}. The inputs are {known}.")
            if value is None:
                continue
            if key in self._activations:
                active[self._activations[key]] = bool(_flag(value, key))
                continue
            i, p = self._inputs[key], self.points.inputs[self._inputs[key]]
            x = number(value, key)
            lo, hi = p.minimum, p.maximum
            if lo is not None and x < lo or hi is not None and x > hi:
                bound = lo if lo is not None and x < lo else hi
                side = "minimum" if bound == lo else "maximum"
                alerts.append(f"WARNING: value {x:g} for input {key} is outside its {side} {bound:g} {p.unit or ''}; "
                              f"it was saturated to {bound:g}")  # fmt: skip
                x = bound
            values[i] = x
        for i, p in enumerate(self.points.inputs):
            if active[i] and math.isnan(values[i]):
                raise TestError(400, f"{activation(p.name)} is 1 but {p.name} is not given: give the value to apply")
        return values, active, alerts

    def _step(self, action: list[float], applied: list) -> None:
        self.sim.send(action)
        _, _, terminated, info = self.sim.receive()
        self.ended = bool(terminated)
        self._observe(info, applied)

    def _observe(self, info: dict, applied: list) -> None:
        """The state after a step (BOPTEST's payload: time, every input and measurement), kept for `results`."""
        t = info["time"]  # the year's end is the next year's January 1, 00:00: seconds from the start's year
        self.now_s = (t - dt.datetime(self.year, 1, 1)).total_seconds()
        state = {"time": self.now_s}
        for i, (p, v) in enumerate(zip(self.points.inputs, applied, strict=True)):
            own = self.building.own[i][0] if i < len(self.building.own) else None
            if v is None and own is not None:  # not overwritten: the building's own schedule's value
                v = p.to_si(info[own])
            state[p.name] = v
            state[activation(p.name)] = int(applied[i] is not None)
        for p in self.points.measurements:
            v = info[p.source]
            state[p.name] = p.to_si(v) if math.isfinite(v) else None
        self.state = state
        for k, v in state.items():
            self.results.setdefault(k, []).append(v)

    # -- queries ----------------------------------------------------------------------------------
    def results_query(self, point_names, start_time, final_time):
        start, final = number(start_time, "start_time"), number(final_time, "final_time")
        names = _names(point_names)
        have = [p.name for p in self.points.inputs] + list(self._activations)
        have += [p.name for p in self.points.measurements]
        wrong = [n for n in names if n not in have]
        if wrong:
            raise TestError(400, f"Invalid point name(s) {wrong} in point_names. The inputs and measurements are "
                                 f"{have}.")  # fmt: skip
        times = self.results.get("time", [])
        rows = [i for i, t in enumerate(times) if start <= t <= final]
        payload = {"time": [times[i] for i in rows]}
        payload |= {n: [self.results[n][i] for i in rows] for n in names}
        return f"Queried results data successfully for point names {names}.", payload

    def forecast(self, point_names, horizon, interval):
        from parallel_eplus.deploy.boptest.forecast import forecast_times

        names = _names(point_names)
        have = [p.name for p in self.points.forecasts]
        wrong = [n for n in names if n not in have]
        if wrong:
            raise TestError(400, f"Invalid point name(s) {wrong} in point_names. The forecast points are {have}.")
        try:
            times = forecast_times(self.now_s, number(horizon, "horizon"), number(interval, "interval"))
            now = dt.datetime(self.year, 1, 1) + dt.timedelta(seconds=self.now_s)
            values = weather_forecast(self.epw, self.year, times, self.scenario, now)
        except ForecastError as e:
            raise TestError(400, str(e)) from None
        values |= price_forecast(self.tariffs, self.emission_factor, self.year, times)
        return "Queried the forecast data successfully.", {"time": times.tolist()} | {n: values[n] for n in names}

    def set_scenario(self, given):
        if not isinstance(given, dict):
            raise TestError(400, 'the body must be a JSON object: {"electricity_price": ..., "time_period": ...}')
        try:
            changed = self.scenario.update(given)
            period = None
            if given.get("time_period") is not None:
                period = test_period(self.building, self.weather, given["time_period"], self.cache / self.testcase)
        except ScenarioError as e:
            raise TestError(400, str(e)) from None
        if period is not None:
            start = (period.start_day - 1 + period.warmup_days) * DAY_S
            _, state = self.initialize(start, period.warmup_days * DAY_S, start + PERIOD_S, period.weekday)
            changed["time_period"] = state
        else:  # BOPTEST starts its KPIs afresh when the scenario changes
            self.kpi_s, self.time_ratios, self._tic = self.now_s, [], None
            self._restart_kpis()
        return "Test case scenario was set successfully.", changed

    def kpi(self):
        """The KPIs so far: the steps new since the last request folded into the running totals (kpi.py)."""
        if self.sim is None or self._recorder is None:
            return "Queried KPIs successfully (no step yet: initialize and advance).", self._no_kpis()
        price = self.scenario.electricity_price
        if self._totals is None or self._totals_price != price:
            self._totals, self._totals_price, self._folded = Totals(self._comfort()), price, self._kpi_row
        n = self._recorder.n
        if n > self._folded:
            self._totals.add(self._scored(self._folded, n))
            self._folded = n
        return "Queried KPIs successfully.", kpi_payload(self._totals, self._floor_area(), self._time_rat())

    def kpi_recomputed(self) -> dict:
        """The KPIs recomputed over every scored step at once, as `kpi` computed them before it kept running totals:
        what `kpi`'s must equal (the tests check it)."""
        if self.sim is None or self._recorder is None:
            return self._no_kpis()
        steps = self._scored(self._kpi_row, self._recorder.n)
        mean = sum(self.time_ratios) / len(self.time_ratios) if self.time_ratios else None
        return core_kpis(steps, self._comfort(), self._floor_area(), mean)

    def _restart_kpis(self) -> None:
        """The KPIs count from here (initialize, a new scenario)."""
        self._kpi_row = self._folded = self._recorder.n if self._recorder is not None else 0
        self._totals, self._ratio_sum = None, 0.0

    def _scored(self, first: int, last: int):
        """The step table of the recorded rows [first, last) after the KPIs' start time."""
        part = copy.copy(self._recorder)  # the recorder's own table-building, over these rows only
        part.rows, part.times = self._recorder.rows[first:last], self._recorder.times[first:last]
        steps = part.frame()
        return steps[steps["time"] > dt.datetime(self.year, 1, 1) + dt.timedelta(seconds=self.kpi_s)]

    def _comfort(self):
        return scenario_comfort(self.building.comfort, self.tariffs.get(self.scenario.electricity_price))

    def _floor_area(self) -> float | None:
        if self._area is None and self.sim is not None and self.sim.episode_dir is not None:
            self._area = self.building.comfort.kpis.floor_area_m2 if self.building.comfort.kpis else None
            self._area = self._area or floor_area(self.sim.episode_dir / "eplusout.eio")
        return self._area

    def _time_rat(self) -> float | None:
        return self._ratio_sum / len(self.time_ratios) if self.time_ratios else None

    def _no_kpis(self) -> dict:
        return core_kpis(_empty(), self.building.comfort, None, None)

    def process_ids(self) -> list[int]:
        """The EnergyPlus process this test runs (for the tests' checks)."""
        proc = self.sim.proc if self.sim is not None else None
        return [proc.pid] if proc is not None else []

    def close(self) -> None:
        self._recorder, self._totals = None, None
        if self.sim is not None:
            sim, self.sim = self.sim, None
            sim.close()


def _names(point_names) -> list[str]:
    if not isinstance(point_names, list) or not all(isinstance(n, str) for n in point_names):
        raise TestError(400, f"point_names is {point_names!r}: it must be a list of point names")
    return point_names


def _empty():
    import pandas as pd

    return pd.DataFrame({"time": pd.to_datetime([])})
