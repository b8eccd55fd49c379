"""The planner's view of the weather: one interface, three sources (the file, the file with BOPTEST's errors, a
caller's forecast), and `evaluate --planner` choosing among them on a real episode."""

from __future__ import annotations

import datetime as dt
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from parallel_eplus.buildings.building import weather_path
from parallel_eplus.buildings.weather.forecast import ErroredForecast, GivenForecast, PerfectForecast
from parallel_eplus.evaluation.sweep import run_sweep
from parallel_eplus.learning.model_based.control.saved_planner import PlannerOptions, planner_controller
from parallel_eplus.learning.model_based.runtime.features import exogenous, step_times

ROOT = Path(__file__).resolve().parents[1]
PLANNER = ROOT / "results/model-based/datacenter-2zone/runs/datacenter-2zone-mpc-seed0/best/planner"
EPW = weather_path("datacenter-2zone", "CA")


def hours(start: dt.datetime, n: int) -> list[dt.datetime]:
    return [start + dt.timedelta(hours=k) for k in range(n)]


def test_the_perfect_forecast_is_the_files_hourly_values_and_interpolates_between_them():
    f = PerfectForecast(EPW)
    noon = dt.datetime(2013, 7, 2, 12)
    at_hours = f.weather(noon, hours(noon, 3))
    rows = f.hourly[(182 * 24 + 11) : (182 * 24 + 14)]  # value i of the file is the hour ending at i + 1
    assert np.allclose(at_hours, rows)
    half = f.weather(noon, [noon + dt.timedelta(minutes=30)])[0]
    assert np.allclose(half, (rows[0] + rows[1]) / 2)


def test_forecast_errors_grow_with_the_lead_time_are_redrawn_each_hour_and_repeat_for_the_same_hour():
    truth, errored = PerfectForecast(EPW), ErroredForecast(EPW, "high", seed=3)
    lead = [dt.timedelta(minutes=15 * (k + 1)) for k in range(8)]
    gaps = []
    for h in range(24 * 60):  # every hour of 60 days
        now = dt.datetime(2013, 3, 1) + dt.timedelta(hours=h)
        times = [now + d for d in lead]
        gaps.append(errored.weather(now, times)[:, 0] - truth.weather(now, times)[:, 0])
    gaps = np.array(gaps)
    assert gaps[:, -1].std() > gaps[:, 0].std() > 0.5  # BOPTEST's "high": K0 1.5 K, growing along the horizon
    now = dt.datetime(2013, 3, 5, 10)
    same = [errored.weather(now + dt.timedelta(minutes=m), step_times(now, 15, 4)) for m in (0, 30)]
    assert np.array_equal(same[0], same[1])  # one draw per hour
    assert not np.array_equal(same[0], ErroredForecast(EPW, "high", seed=4).weather(now, step_times(now, 15, 4)))
    rh = errored.weather(now, step_times(now, 15, 4))[:, 1]
    assert np.array_equal(rh, truth.weather(now, step_times(now, 15, 4))[:, 1])  # BOPTEST models no humidity error
    with pytest.raises(ValueError, match="low, medium, high"):
        ErroredForecast(EPW, "huge")


def test_a_callers_forecast_becomes_the_same_model_inputs_as_the_file_it_came_from():
    now = dt.datetime(2013, 1, 5, 10)
    times = step_times(now, 15, 8)
    values = PerfectForecast(EPW).weather(now, times)
    given = GivenForecast(np.array(values.tolist()))
    assert np.array_equal(exogenous(given.weather(now, times), times, None), exogenous(values, times, None))


def test_planner_options_are_checked_before_anything_runs():
    assert PlannerOptions.parse("forecast=medium,candidates=128") == PlannerOptions("medium", "candidates=128")
    with pytest.raises(ValueError, match="forecast='great'"):
        PlannerOptions.parse("forecast=great")
    with pytest.raises(ValueError, match="NAME one of"):
        planner_controller(f"{PLANNER}=P", "candidate=12")
    with pytest.raises(ValueError, match="comfort_risk"):
        PlannerOptions.parse("comfort_risk=best")


@pytest.mark.slow
def test_a_planner_with_forecast_errors_plans_differently_on_the_same_day(tmp_path, no_leaks):
    perfect = planner_controller(f"{PLANNER}=Perfect")
    errored = planner_controller(f"{PLANNER}=Errored", "forecast=high")
    df = run_sweep([perfect, errored], ["CA"], 1, 2, tmp_path, progress=False, building="datacenter-2zone")
    a, b = (pd.read_parquet(Path(d) / "steps.parquet") for d in df.episode_dir)
    assert len(a) == len(b) == 96
    assert not np.allclose(a["west_setpoint_c"], b["west_setpoint_c"])  # the forecast reached the plans
    assert df.in_band_pct.min() > 90
