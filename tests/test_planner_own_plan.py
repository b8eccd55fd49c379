"""The planner's baseline (`comfort_reference = "baseline"`): what the building's own controls would set over the
horizon, or its rule (`baseline_source = "rule"`), and the settings that weigh the search's plan against it
(`consensus`, `min_saving`, `baseline_radius`)."""

from __future__ import annotations

import datetime as dt
import json
import shutil
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from parallel_eplus.buildings.building import load_building, weather_path
from parallel_eplus.deploy.serve.planner_runtime import calendar_arrays
from parallel_eplus.evaluation.controllers import Controller
from parallel_eplus.evaluation.sweep import run_sweep
from parallel_eplus.learning.imitation import record_baseline
from parallel_eplus.learning.model_based.control.mpc import MPC, thermostat_sides
from parallel_eplus.learning.model_based.control.saved_planner import PlannerOptions, planner_controller, planner_file
from parallel_eplus.learning.model_based.model.dataset import Transitions
from parallel_eplus.learning.model_based.model.sources import add_baseline
from parallel_eplus.learning.model_based.runtime.calendar import Calendar, own_reference
from parallel_eplus.learning.model_based.runtime.features import step_times
from parallel_eplus.learning.model_based.runtime.planner import PlanRequest, _follow
from parallel_eplus.learning.model_based.settings import MPCSettings
from parallel_eplus.training.config import ComfortConstraint, TrainConfig
from parallel_eplus.training.train import train

ROOT = Path(__file__).resolve().parents[1]
PLANNER = ROOT / "results/model-based/datacenter-2zone/runs/datacenter-2zone-mpc-seed0/best/planner"
OFFICE = ROOT / "results/model-based/office-small/runs/office-small-mpc-seed0/planner"


def test_the_own_reference_sets_each_thermostat_to_its_zone_s_own_setpoint():
    office = load_building("office-small")
    sides = thermostat_sides(office)
    assert sides == [(0, 1), (0, 0)]  # cooling, heating: the core zone's thermostat (all five share its schedules)
    low, high = (np.array([getattr(a, k) for a in office.actions], np.float32) for k in ("low", "high"))
    bounds = np.zeros((3, 5, 2), np.float32)
    bounds[..., 0], bounds[..., 1] = 15.4, 26.9  # the setbacks 15.6 and 26.7, widened by the 0.2 K tolerance
    ref = own_reference(bounds, 0.2, sides, low, high, np.zeros(2, np.float32))
    physical = low + (ref + 1) / 2 * (high - low)
    np.testing.assert_allclose(physical, np.broadcast_to([26.7, 15.6], (3, 2)), atol=1e-5)
    held = own_reference(bounds, 0.2, [None, (0, 0)], low, high, np.array([0.3, 0.0], np.float32))
    assert np.all(held[:, 0] == np.float32(0.3))  # not a thermostat: held where it is
    recorded = np.array([[0.5, 0.9], [np.nan, 0.9], [-0.2, 0.9]], np.float32)  # what the own controls set then
    dated = own_reference(bounds, 0.2, [None, (0, 0)], low, high, np.array([0.3, 0.0], np.float32), recorded)
    np.testing.assert_array_equal(dated[:, 0], np.float32([0.5, 0.3, -0.2]))  # as recorded, held where not
    np.testing.assert_array_equal(dated[:, 1], held[:, 1])  # a thermostat follows its zone's schedule


@pytest.mark.slow
def test_a_supply_air_node_s_own_plan_is_what_its_manager_set_that_day(tmp_path, no_leaks):
    """The medium office's supply air follows no thermostat schedule: its own plan is what the model's own manager
    set on that date, recorded with the building's own controls. The calendar keeps it by date (and the served
    planner's arrays the same), and `baseline_radius` keeps the planner's supply air that near it, as the
    thermostats."""
    mpc = MPC("office-medium", MPCSettings(comfort_reference="baseline", baseline_radius=0.1), 0.5, 1e-5, 1)
    assert mpc.follows.tolist() == [True, True, False]  # before the record: the thermostats only
    demos = record_baseline("office-medium", ["CA"], 1, 1, tmp_path / "record", progress=False)
    own = np.array([side is None for side in mpc.thermostat_sides])
    add_baseline(Transitions(mpc.layout), demos, mpc, lambda t, v: True, 0, own)
    assert mpc.follows.all()
    row, h = 40, mpc.settings.horizon
    info = {"time": demos.times[row], "weather": "CA"}
    a_last = demos.actions[row - 1 : row].copy()
    a_last[0, 2] = 0.5  # the supply air where the planner left it: 16.5 C
    plan = mpc.baseline_plan([info], mpc.future([info])[2], a_last)[0]
    np.testing.assert_allclose(plan[:, 2], demos.actions[row : row + h, 2])  # each step: what the manager set
    assert np.all(np.abs(plan[:, 2] - 0.5) > 0.5)  # (12.8 C in January), not where it was left
    times = step_times(info["time"], mpc.step_minutes, h)
    served = Calendar.from_arrays(mpc.comfort_times.settings(), calendar_arrays(mpc.comfort_times))
    np.testing.assert_array_equal(served.own_actions(times), mpc.comfort_times.own_actions(times))
    action = mpc.act(demos.observations[row : row + 1], [info], a_last)
    reference = _follow(a_last, plan[None], mpc.settings.max_increment, *mpc.support)
    assert abs(action[0, 2] - reference[0, 0, 2]) <= 0.1 + 1e-5


def test_the_reference_candidate_makes_up_a_jump_it_cannot_make_at_once():
    """From a setback at the top of the range to an occupied setpoint 1.5 away, 0.15 a step: there in ten steps
    and held (clipping each step's increment alone left it 0.15 from the start for the whole horizon)."""
    target = np.full((1, 12, 1), -0.5, np.float32)
    path = _follow(np.ones((1, 1), np.float32), target, 0.15, np.full(1, -1.0), np.full(1, 1.0))
    np.testing.assert_allclose(path[0, :, 0], [0.85, 0.7, 0.55, 0.4, 0.25, 0.1, -0.05, -0.2, -0.35, -0.5, -0.5, -0.5],
                               atol=1e-6)  # fmt: skip
    inside = _follow(np.ones((1, 1), np.float32), target, 1.0, np.full(1, 0.0), np.full(1, 1.0))
    assert np.all(inside == 0.0)  # the support's edge, where the target lies beyond it


def test_the_own_jump_is_the_morning_setpoint_step_the_calendar_recorded():
    """The office heats from its 15.6 C setback to 21 C in one step, on a 15-22 C action: 1.54 normalized,
    beyond the 1.0 its planners were trained with (the warning at training's start); no thermostat, no jump."""
    office = MPC.load(planner_file(OFFICE))
    assert office.own_jump() == pytest.approx(2 * (21.0 - 15.6) / (22.0 - 15.0), abs=1e-4)
    assert MPC.load(planner_file(PLANNER)).own_jump() == 0.0  # the data center: no thermostat action


def _decisions(options: str, members: bool = False, own_cost: bool = False) -> tuple[MPC, list[dict]]:
    """The office planner under `options` at each hour of an April and a July day (zones at 22 and 25 C): its
    action; the own plan as a candidate can follow it; the search's cost; with `members`, each member's predicted
    cost of the plan the search chose and of the own plan (`members=True`) and their mean; with `own_cost`, the own
    plan's cost alone."""
    a_last = np.array([[0.5, -0.5]], np.float32)
    mpc = PlannerOptions.parse(options).apply(MPC.load(planner_file(OFFICE)))
    decisions = []
    for month, outdoor, zone in ((4, 15.0, 22.0), (7, 30.0, 25.0)):
        obs = np.array([[outdoor, *[zone] * 5, 3000.0, 0.0, 0.0, 0.5]], np.float32)
        s = mpc.layout.state(obs[:, : len(mpc.layout.sensors)])
        for hour in range(24):
            info = {"time": dt.datetime(2013, month, 8, hour, 0), "weather": "CA"}
            exo, applies, bounds, weights = mpc.future([info])
            reference = _follow(a_last, mpc.baseline_plan([info], bounds, a_last), mpc.settings.max_increment,
                                *mpc.support)  # fmt: skip
            action = mpc.act(obs, [info], a_last)
            steps = np.concatenate([np.zeros((1, 1, 2)), np.cumsum(mpc.last.increments[:, :-1], axis=1)], axis=1)
            pair = np.stack([action[:, None] + steps, reference], axis=1).astype(np.float32)
            seen = PlanRequest(s, a_last, exo, applies, bounds, mpc.comfort_weight, mpc.support, mpc.warm, [0],
                               energy_weights=weights, reference=reference)  # fmt: skip
            d = {"key": (month, hour), "action": action, "reference": reference[:, 0], "cost": mpc.last.cost[0]}
            if members:  # [E, W, 2]: the chosen plan's, the own plan's
                d |= {"members": mpc.planner._cost(seen, pair, members=True), "mean": mpc.planner._cost(seen, pair)[0]}
            if own_cost:
                d["own_cost"] = mpc.planner._cost(seen, reference[:, None])[0][0, 0]
            decisions.append(d)
    return mpc, decisions


@pytest.fixture(scope="module")
def own_plan_decisions() -> list[dict]:
    """The planner with the own plan as its reference and no other setting (consensus off, min_saving 0, no radius):
    the decisions each test below weighs its setting against, made once."""
    return _decisions("comfort_reference=baseline", members=True, own_cost=True)[1]


def _left(d: dict) -> bool:
    """Whether the planner left the own plan's action."""
    return not np.allclose(d["action"], d["reference"], atol=1e-6)


def test_with_consensus_the_planner_leaves_the_own_plan_only_where_every_member_prefers_its_plan(own_plan_decisions):
    """Each member's cost (`members=True`) averages to the planner's; with `consensus`, the action is the own plan's
    unless every member predicts the plan the search chose costs less; without it, the search's best plan acts
    where some member prefers the own plan (April and July nights here)."""
    outcomes = {}
    with_it = _decisions("comfort_reference=baseline,consensus=true", members=True)[1]
    for consensus, decisions in (("false", own_plan_decisions), ("true", with_it)):
        for d in decisions:
            per = d["members"]
            np.testing.assert_allclose(per.mean(0), d["mean"], rtol=1e-4, atol=1e-4)
            outcomes[(consensus, *d["key"])] = (not _left(d), bool(np.all(per[:, 0, 0] < per[:, 0, 1])))
    with_consensus = [v for k, v in outcomes.items() if k[0] == "true"]
    assert all(own or preferred for own, preferred in with_consensus)  # left only where every member preferred
    assert any(not own for own, _ in with_consensus)  # and it did leave it
    assert any(not own and not preferred for (c, *_), (own, preferred) in outcomes.items() if c == "false")


def test_with_a_minimum_saving_the_planner_leaves_the_own_plan_only_for_that_much_less_predicted_cost(
    own_plan_decisions,
):
    """`min_saving`: the own plan's action unless the plan the search chose is predicted to cost at least that share
    less than it over the horizon; a larger share leaves it less often, and 0 as before. Refused without the own
    plan to weigh against."""
    left = {}
    for share in (0.0, 0.02, 0.5):
        options = f"comfort_reference=baseline,min_saving={share}"
        decisions = own_plan_decisions if share == 0.0 else _decisions(options, own_cost=True)[1]  # 0: the default
        left[share] = 0
        for d in decisions:
            if _left(d):
                left[share] += 1
                assert d["own_cost"] - d["cost"] >= share * abs(d["own_cost"]) - 1e-3  # it paid for leaving
    assert left[0.0] > left[0.02] >= left[0.5] and left[0.0] > 0
    with pytest.raises(ValueError, match="comfort_reference=baseline"):
        PlannerOptions.parse("comfort_reference=band,min_saving=0.02").apply(MPC.load(planner_file(OFFICE)))
    with pytest.raises(ValueError, match="min_saving"):
        PlannerOptions.parse("min_saving=1.5")


def test_with_an_own_radius_the_thermostats_stay_that_near_the_own_plan(own_plan_decisions):
    """`baseline_radius`: every thermostat action within that much (normalized) of the own plan's at the step it acts,
    where without it the search strays further; refused without the own plan."""
    mpc, radius = _decisions("comfort_reference=baseline,baseline_radius=0.1")
    assert mpc.follows.all()  # the office's two actions are its thermostats
    furthest = {r: max(float(np.abs(d["action"] - d["reference"]).max()) for d in decisions)
                for r, decisions in (("", own_plan_decisions), (",baseline_radius=0.1", radius))}  # fmt: skip
    assert furthest[",baseline_radius=0.1"] <= 0.1 + 1e-5 < furthest[""]
    with pytest.raises(ValueError, match="comfort_reference=baseline"):
        PlannerOptions.parse("baseline_radius=0.1").apply(MPC.load(planner_file(OFFICE)))
    with pytest.raises(ValueError, match="baseline_radius"):
        PlannerOptions.parse("comfort_reference=baseline,baseline_radius=3")


@pytest.mark.slow
def test_a_planner_whose_own_plan_is_the_rule_keeps_the_supply_air_near_the_rules(tmp_path, no_leaks):
    """`baseline_source=rule` on the medium office: the own plan of the supply air is Guideline 36's reset (the spec's
    `controller`) run beside the planner, not the building's constant 12.8 C, and `baseline_radius` holds the planner
    within 0.2 (0.6 K) of it at every step; a planner with no rule-based `controller` that releases is refused."""
    settings = MPCSettings(explore_steps=48, refit_every=96, epochs=5, candidates=32, comfort_hours="occupied",
                           comfort_reference="baseline", baseline_source="rule", baseline_radius=0.2,
                           support_margin=2.0, max_increment=2.0, distill=False)  # fmt: skip
    cfg = TrainConfig(algorithm="mpc", building="office-medium", weathers=["CO"], workers=1, run_days=2,
                      timesteps=192, checkpoint_every=96, run_name="ruled", runs_dir=str(tmp_path / "runs"),
                      tensorboard_dir=str(tmp_path / "tb"), mpc=settings,
                      comfort=ComfortConstraint(target_pct=97.5))  # fmt: skip
    train(cfg, progress=False)
    planner = planner_controller(str(tmp_path / "runs" / "ruled" / "planner"))
    df = run_sweep([planner], ["CO"], 1, 1, tmp_path / "eval", progress=False, building="office-medium")
    steps = pd.read_parquet(Path(df["episode_dir"][0]) / "steps.parquet")
    rule = Controller("rule", "rbc").make("office-medium")
    low, high = 12.0, 18.0  # office-medium's supply_air_c
    ruled = np.array([rule(np.zeros(0), row) for row in steps.to_dict("records")])[:, -1]
    ruled_c = low + (ruled + 1) / 2 * (high - low)
    off = np.abs(steps["supply_air_c"].to_numpy()[1:] - ruled_c[:-1])  # each step's action, from the step before
    assert off.max() <= 0.6 + 1e-3, off.max()
    assert (ruled_c > 14.0).mean() > 0.5  # far from the building's own 12.8 C: January in Golden
    # served, the rule rides along (serve/served_rule.py): a day in closed loop over HTTP equals the in-process one
    from parallel_eplus.deploy.export.policy import export
    from parallel_eplus.evaluation.controllers import http_controller

    from .serving import serving

    out = tmp_path / "export"
    export(tmp_path / "runs" / "ruled", out, record_days=1, options="band_thermostats=baseline")  # 48 decisions checked
    contract = json.loads((out / "controller.json").read_text())
    assert [r["name"] for r in contract["rule"]["readings"]] == ["setpoint_clgsetp_sch"]  # the zones' cooling setpoint
    assert contract["planner"]["settings"]["band_thermostats"] == "baseline"
    trusting = tmp_path / "trusting"  # the same planner, never falling back: its arithmetic against in process
    shutil.copytree(out, trusting)
    contract["fallback"] |= {"max_input_z": 1e9, "max_forecast_gap_c": 1e9, "max_spread_k": 1e9}
    (trusting / "controller.json").write_text(json.dumps(contract))
    in_process = planner_controller(f"{tmp_path / 'runs' / 'ruled' / 'planner'}=Planner", "band_thermostats=baseline")
    with serving(trusting, tmp_path / "server.log") as url:
        df = run_sweep([in_process, http_controller(url)], ["FL"], 1, 2, tmp_path / "served", progress=False,
                       building="office-medium")  # fmt: skip
    here, there = (pd.read_parquet(Path(d) / "steps.parquet") for d in df.episode_dir)
    assert here["outdoor_temp_c"].between(16.5, 20.5).any()  # Tampa: the reset between its ends, not only at 18 C
    pd.testing.assert_frame_equal(here, there, check_exact=True)  # every setpoint, every step: the rule's state too

    # falling back, it sends the rule's supply air (and the own thermostats); what the rule reads is required
    from parallel_eplus.buildings.rules.air_reset import advance
    from parallel_eplus.buildings.weather.forecast import WEATHER, PerfectForecast
    from parallel_eplus.deploy.serve.contract import Contract, InputError
    from parallel_eplus.deploy.serve.planner_runtime import PlannerRuntime

    runtime = PlannerRuntime(out, Contract.read(out))
    row = here.iloc[30]
    times = step_times(row["time"].to_pydatetime(), 10, contract["forecast"]["steps"])
    weather = PerfectForecast(weather_path("office-medium", "FL")).truth(times)
    weather[:, 0] += 20.0  # a forecast the outdoor sensor contradicts
    body = {"time": row["time"].isoformat(), "sensors": {i["name"]: float(row[i["name"]]) for i in contract["inputs"]},
            "last_setpoints": {o["name"]: float(row[o["name"]]) for o in contract["outputs"]},
            "forecast": {n: weather[:, i].tolist() for i, n in enumerate(WEATHER)},
            "rule_readings": {"setpoint_clgsetp_sch": 24.0}, "rule_state": {"t_max_c": 16.0}}  # fmt: skip
    answer = runtime.act(body)
    readings = {**body["sensors"], **body["rule_readings"]}
    t_max, ruled = advance(rule.cfg, rule.points, 16.0, readings)
    assert answer["fallback"] and answer["rule_state"] == {"t_max_c": t_max}  # (Tampa: far from its CO data too)
    assert answer["setpoints"]["supply_air_c"]["value"] == pytest.approx(low + (ruled[2] + 1) / 2 * (high - low))
    refused = (
        ("rule_readings", {"rule_readings": None}),
        ("rule_state", {"rule_state": {"t_max_c": 30}}),
        ("setpoint_clgsetp_sch", {"rule_readings": {"setpoint_clgsetp_sch": {"value": 75, "unit": "F"}}}),
        ("rule_readings.zone_c", {"rule_readings": {"setpoint_clgsetp_sch": 24.0, "zone_c": 24.0}}),
    )
    for field, change in refused:
        with pytest.raises(InputError, match=field):
            runtime.act({**body, **change})
    with pytest.raises(ValueError, match="baseline_source=rule"):
        MPC("office-small", MPCSettings(comfort_reference="baseline", baseline_source="rule"), 0.1, 1e-5, 1)
