"""What the planner pays for comfort: `comfort_weight`, `comfort_hours` and `comfort_reference` (settings.py), on
the committed planners. The own plan and the settings that weigh the search's plan against it:
test_planner_own_plan.py."""

from __future__ import annotations

import datetime as dt
from dataclasses import replace
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from parallel_eplus.buildings.building import load_building
from parallel_eplus.learning.imitation import record_baseline
from parallel_eplus.learning.model_based.control.mpc import MPC
from parallel_eplus.learning.model_based.control.saved_planner import PlannerOptions, planner_file
from parallel_eplus.learning.model_based.runtime.features import step_times
from parallel_eplus.learning.model_based.runtime.planner import PlanRequest
from parallel_eplus.learning.model_based.settings import MPCSettings

ROOT = Path(__file__).resolve().parents[1]
PLANNER = ROOT / "results/model-based/datacenter-2zone/runs/datacenter-2zone-mpc-seed0/best/planner"
OFFICE = ROOT / "results/model-based/office-small/runs/office-small-mpc-seed0/planner"


def test_planner_options_replace_the_saved_comfort_settings():
    """`--planner comfort_weight=W` plans with W, not with the multiplier the run ended with; `comfort_hours`
    reaches the calendar the planner reads."""
    saved = MPC.load(planner_file(PLANNER))
    other = PlannerOptions.parse("candidates=64").apply(MPC.load(planner_file(PLANNER)))
    assert other.comfort_weight == saved.comfort_weight != 3.5
    assert PlannerOptions.parse("comfort_weight=3.5").apply(saved).comfort_weight == 3.5
    assert not saved.comfort_times.occupied_only
    assert PlannerOptions.parse("comfort_hours=occupied").apply(saved).comfort_times.occupied_only


def test_a_candidate_that_plays_the_reference_pays_for_no_discomfort():
    """Against the bound, a plan that lets the office drift pays for it; measured against itself, nothing."""
    mpc = MPC.load(planner_file(OFFICE))
    info = {"time": dt.datetime(2013, 1, 8, 7, 0), "weather": "CA"}
    exo, applies, bounds, weights = mpc.future([info])
    obs = np.array([[8.0, 15.0, 15.0, 15.0, 15.0, 15.0, 3000.0, 0.0, 0.0, 0.0]], np.float32)
    s = mpc.layout.state(obs[:, : len(mpc.layout.sensors)])
    a_last = np.array([[1.0, -1.0]], np.float32)  # the setbacks' far ends: cold at the day's start
    plans = np.repeat(a_last[:, None, None, :], mpc.settings.horizon, axis=2)  # [1, 1, H, A]
    seen = PlanRequest(s, a_last, exo, applies, bounds, 0.0, mpc.support, mpc.warm, [0], energy_weights=weights)
    free, _ = mpc.planner._cost(seen, plans)
    paid, _ = mpc.planner._cost(replace(seen, comfort_weight=100.0), plans)
    relative, _ = mpc.planner._cost(replace(seen, comfort_weight=100.0, reference=plans[:, 0]), plans)
    assert paid[0, 0] > free[0, 0] + 1  # out of its bounds at 07:00: the comfort term is paid
    np.testing.assert_allclose(relative, free, rtol=1e-5)


def test_comfort_level_own_needs_a_comfort_target(tmp_path):
    from parallel_eplus.training.config import ComfortConstraint, TrainConfig

    with pytest.raises(ValueError, match="comfort_level=baseline .* --comfort-target"):
        TrainConfig(algorithm="mpc", mpc=MPCSettings(comfort_level="baseline"), runs_dir=str(tmp_path)).resolved()
    with pytest.raises(ValueError, match="comfort_level 'mine'"):
        MPCSettings(comfort_level="mine")
    TrainConfig(algorithm="mpc", mpc=MPCSettings(comfort_level="baseline"), comfort=ComfortConstraint(99.8),
                runs_dir=str(tmp_path)).resolved()  # fmt: skip


def test_comfort_reference_own_is_refused_where_no_action_is_a_thermostat():
    with pytest.raises(ValueError, match="no thermostat action"):
        PlannerOptions.parse("comfort_reference=baseline").apply(MPC.load(planner_file(PLANNER)))


@pytest.mark.slow
def test_a_planner_paying_beyond_its_own_thermostats_in_occupied_hours_exports_and_serves_the_same(tmp_path):
    """The export's own check: the served planner answers sampled decisions exactly as the in-process one."""
    import json
    import shutil

    from parallel_eplus.buildings.weather.forecast import WEATHER
    from parallel_eplus.deploy.export.policy import export
    from parallel_eplus.deploy.serve.contract import Contract
    from parallel_eplus.deploy.serve.planner_runtime import PlannerRuntime

    options = PlannerOptions.parse("comfort_reference=baseline,comfort_hours=occupied")
    mpc = options.apply(MPC.load(planner_file(OFFICE)))
    folder = tmp_path / "run" / "planner"
    mpc.save(folder / "planner.pt")
    shutil.copy(OFFICE / "config.json", folder / "config.json")
    export(folder, tmp_path / "served", record_days=1)
    planner = Contract.read(tmp_path / "served").data["planner"]
    assert planner["comfort_reference"] == "baseline" and planner["calendar"]["occupied_only"] is True
    assert planner["thermostat_sides"] == [[0, 1], [0, 0]]
    # a cold morning, where paying only beyond the own thermostats' discomfort changes the plan
    runtime = PlannerRuntime(tmp_path / "served", Contract.read(tmp_path / "served"))
    when, last = dt.datetime(2013, 1, 8, 7, 0), np.array([24.0, 21.0])
    obs = np.array([[8.0, 18.0, 18.0, 18.0, 18.0, 18.0, 3000.0, 0.0, 0.0, 0.0]], np.float32)
    sensors = [i["name"] for i in json.loads((tmp_path / "served" / "controller.json").read_text())["inputs"]]
    truth = mpc.forecasts("CA").file.truth(step_times(when, mpc.step_minutes, mpc.settings.horizon))
    body = {"time": when.isoformat(), "sensors": dict(zip(sensors, map(float, obs[0, : len(sensors)]), strict=True)),
            "last_setpoints": {"cooling_setpoint_c": 24.0, "heating_setpoint_c": 21.0},
            "forecast": {n: truth[:, i].tolist() for i, n in enumerate(WEATHER)}}  # fmt: skip
    answer = runtime.act(body)["setpoints"]
    served = np.array([answer[n]["value"] for n in ("cooling_setpoint_c", "heating_setpoint_c")])
    a_last = (2 * (last - mpc.action_low) / (mpc.action_high - mpc.action_low) - 1).astype(np.float32)[None]
    info = {"time": when, "weather": "CA"}
    own = mpc.act(obs, [info], a_last)[0]
    mpc.reset(0)
    bound = PlannerOptions.parse("comfort_reference=band").apply(mpc).act(obs, [info], a_last)[0]
    assert not np.allclose(own, bound)  # the reference reached the plan
    np.testing.assert_allclose(served, mpc.action_low + (own + 1) / 2 * (mpc.action_high - mpc.action_low), atol=1e-4)
    # held near the own plan, and off it only for a 2 % saving: served as planned in process
    options = "comfort_reference=baseline,comfort_hours=occupied,baseline_radius=0.1,min_saving=0.02"
    mpc = PlannerOptions.parse(options).apply(MPC.load(planner_file(OFFICE)))
    mpc.save(folder / "planner.pt")
    export(folder, tmp_path / "served-near", record_days=1)
    assert Contract.read(tmp_path / "served-near").data["planner"]["settings"]["baseline_radius"] == 0.1
    runtime = PlannerRuntime(tmp_path / "served-near", Contract.read(tmp_path / "served-near"))
    answer = runtime.act(body)["setpoints"]
    served = np.array([answer[n]["value"] for n in ("cooling_setpoint_c", "heating_setpoint_c")])
    near = mpc.act(obs, [info], a_last)[0]
    np.testing.assert_allclose(served, mpc.action_low + (near + 1) / 2 * (mpc.action_high - mpc.action_low), atol=1e-4)


@pytest.mark.slow
def test_the_own_level_counts_the_own_controls_as_their_evaluation_scores_them(tmp_path, no_leaks):
    """`comfort_level=baseline`: the share out of band the record gives the multiplier, date by date, is the share
    `evaluate` scores the building's own controls with over the same days (the office on CO, January 1-4 of
    2017: a Sunday, then workdays with cold mornings)."""
    from parallel_eplus.evaluation.controllers import Controller
    from parallel_eplus.evaluation.sweep import run_sweep
    from parallel_eplus.learning.model_based.model.own_level import BatchComfort, OwnLevel

    office = load_building("office-small")
    comfort = office.comfort
    # the record pairs each observation with the next action: five days cover the four evaluated steps' ends
    demos = record_baseline("office-small", ["CO"], 5, 1, tmp_path / "record", progress=False)
    level = OwnLevel.from_record(demos, [s.name for s in office.observed], list(office.temperatures), comfort,
                                 lambda t, v: comfort.applies(t, v), office.steps_per_day)  # fmt: skip
    df = run_sweep([Controller("Baseline", "baseline")], ["CO"], 4, 1, tmp_path / "eval", False,
                   building="office-small")  # fmt: skip
    steps = pd.read_parquet(Path(df["episode_dir"][0]) / "steps.parquet")
    applied = steps["time"][steps["comfort_applies"].astype(bool)].dt.to_pydatetime()
    counts = [level.count("CO", t) for t in applied]
    assert None not in counts and len(counts) > 200  # every occupied step evaluated is in the record
    out = sum(counts)
    share_out = 100 * out / (len(counts) * level.zones)
    assert share_out > 0.5  # cold mornings: the count has something to count
    assert share_out == pytest.approx(100 - df["in_band_pct"].iloc[0], abs=1e-9)
    assert level.count("CO", dt.datetime(2017, 1, 1, 12, 0)) is None  # a Sunday: the band did not apply
    assert level.allowed_pct(99.8, out, len(counts) * level.zones) == pytest.approx(share_out)
    assert level.allowed_pct(90.0, out, len(counts) * level.zones) == 10.0  # the target's, where larger
    # as many zone samples again on steps the record does not know: those count at the target's 0.2 %
    matched = len(counts) * level.zones
    assert level.allowed_pct(99.8, out, matched, matched) == pytest.approx((share_out + 0.2) / 2)
    batch = BatchComfort()  # the Dyna loop's tally, step by step: the same share
    for c in counts:
        batch.add(0, level.zones, c, level)
    for _ in counts:
        batch.add(0, level.zones, None, level)
    assert batch.allowed_pct(99.8, level) == pytest.approx((share_out + 0.2) / 2)
    assert batch.allowed_pct(99.8, None) is None
    again = OwnLevel.from_state(level.state(tensors=True))  # a checkpoint's round trip
    np.testing.assert_array_equal(again.out["CO"], level.out["CO"])
