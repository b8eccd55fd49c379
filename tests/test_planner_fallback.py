"""The exported planner's fallback on a building nobody tuned (issue 87, item 11): the building's own setpoints at
each date and time (not January's hourly means), a disagreement threshold that trips on what the model has not
seen and not on its data, and a documented first request the planner answers."""

from __future__ import annotations

import copy
import datetime as dt
import json
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from parallel_eplus.deploy.export.planner import _initial
from parallel_eplus.deploy.export.policy import export
from parallel_eplus.deploy.serve.contract import Contract
from parallel_eplus.deploy.serve.own_setpoints import OwnSetpoints, own_table
from parallel_eplus.deploy.serve.planner_runtime import PlannerRuntime

ROOT = Path(__file__).resolve().parents[1]
VAV = ROOT / "results/model-based/office-medium-dcv/runs/office-medium-dcv-mpc-seed0/planner"  # committed


def _schedule(t: dt.datetime) -> tuple[float, float]:
    """A setback heating schedule (21 °C on weekdays 06:00-22:00, else 15.6 °C) and a supply air that follows
    the season (12.8 °C in winter, 14.0 °C from May to September)."""
    occupied = t.weekday() < 5 and 6 <= t.hour < 22
    return 21.0 if occupied else 15.6, 14.0 if 5 <= t.month <= 9 else 12.8


def test_the_fallback_sets_what_the_own_schedules_set_at_that_date_and_time():
    start = dt.datetime(2017, 1, 1)  # a Sunday, as the weather's year runs
    times = [start + dt.timedelta(minutes=15 * k) for k in range(365 * 96)]
    own = OwnSetpoints(own_table(times, np.array([_schedule(t) for t in times]), 15), 15)
    for when in (dt.datetime(2021, 7, 14, 7, 0), dt.datetime(2021, 7, 14, 5, 45), dt.datetime(2021, 7, 18, 7, 0),
                 dt.datetime(2030, 1, 2, 21, 45), dt.datetime(2024, 12, 31, 12, 0),
                 dt.datetime(2024, 2, 29, 6, 0)):  # fmt: skip
        assert tuple(own(when)) == _schedule(when), when  # July's, the schedule's values, the request's weekday
    two_days = OwnSetpoints(own_table(times[:192], np.array([_schedule(t) for t in times[:192]]), 15), 15)
    assert tuple(two_days(dt.datetime(2021, 7, 14, 7))) == (15.6, 12.8)  # a short record: its nearest day
    legacy = OwnSetpoints({"own_controls": np.arange(12 * 24 * 2, dtype=float).reshape(12, 24, 2)}, 15)
    assert tuple(legacy(dt.datetime(2021, 2, 1, 3, 30))) == (2 * (24 + 3), 2 * (24 + 3) + 1)  # older exports


def test_a_first_setpoint_the_model_never_saw_is_replaced_by_one_the_own_controls_set():
    """A setback group whose spec says 21 °C where the data held 15.6 °C (29 standard deviations away)."""
    actions = [SimpleNamespace(name="heating", low=15.0, high=25.0, initial=21.0),
               SimpleNamespace(name="cooling", low=20.0, high=30.0, initial=24.0)]  # fmt: skip
    layout = SimpleNamespace(n_state=1)
    x_mean, x_std = np.array([20.0, -0.88, 0.0, -0.88, 0.0]), np.array([3.0, 0.03, 0.5, 0.03, 0.5])
    record = np.array([[15.6, 26.7]] * 90 + [[16.0, 24.0]] * 10)
    got = _initial(actions, SimpleNamespace(physical=record), SimpleNamespace(x_mean=x_mean, x_std=x_std), layout)
    assert got == [15.6, 24.0]


@pytest.fixture(scope="module")
def exported(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("vav")
    export(VAV, out, record_days=1, options="band_thermostats=baseline", progress=False)  # the settings
    return out


@pytest.fixture(scope="module")
def runtime(exported) -> PlannerRuntime:
    return PlannerRuntime(exported, Contract.read(exported))


@pytest.mark.slow
def test_the_contract_documents_a_first_request_inside_the_data(exported, runtime):
    c = json.loads((exported / "controller.json").read_text())
    example = c["example"]
    assert example["last_setpoints"] == {o["name"]: o["initial"] for o in c["outputs"]}
    answer = runtime.act(copy.deepcopy(example))
    assert answer["fallback"] is False, answer.get("reason")
    # what the model has seen, its members agree on: no step of the own record trips the threshold
    limit = c["fallback"]["max_step_spread_k"]
    assert c["export_check"]["step_spread_k_max"] < limit < 2.5 and answer["step_spread_k"] < limit


def _unseen(runtime, example, **sensors) -> dict:
    body = copy.deepcopy(example)
    body["sensors"].update(sensors)
    if "outdoor_temp_c" in sensors:  # a forecast that agrees with the reading: only the model can doubt it
        body["forecast"].update(outdoor_drybulb_c=[sensors["outdoor_temp_c"]] * len(body["forecast"]["outdoor_rh_pct"]),
                                global_horizontal_w_m2=[1200.0] * len(body["forecast"]["outdoor_rh_pct"]))  # fmt: skip
    return runtime.act(body)


@pytest.mark.slow
def test_a_reading_and_a_forecast_the_model_never_met_fall_back_to_the_own_setpoints_then(exported, runtime):
    example = json.loads((exported / "controller.json").read_text())["example"]
    zones = [s for s in example["sensors"] if s.endswith("_temp_c") and s != "outdoor_temp_c"]
    own = OwnSetpoints(dict(np.load(exported / "planner.npz")), 15)(dt.datetime.fromisoformat(example["time"]))
    for answer in (
        _unseen(runtime, example, **dict.fromkeys(zones, 30.0)),  # within max_input_z of the data
        _unseen(runtime, example, outdoor_temp_c=48.0),
    ):  # 48 °C and full sun on a January day
        assert answer["fallback"] is True and "disagree" in answer["reason"] and "coming step" in answer["reason"]
        values = [v["value"] for v in answer["setpoints"].values()]  # the thermostats' as recorded; the supply air
        assert np.allclose(values[:2], own[:2]) and (values[0], values[1]) == (26.7, 15.6)  # the rule's (it rides it)
    recorded = np.load(exported / "planner.npz")
    assert "own_controls_at" in recorded and recorded["own_controls"].shape[1] == len(own)
