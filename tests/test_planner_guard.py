"""The tests for leaving the own plan that read the building, not the model: `band_thermostats` (a thermostat
conditions at least as much as its own plan where the band applies, or follows it) and `guard_k` (what a move off
the own plan cost, measured at the step's end)."""

from __future__ import annotations

import datetime as dt
from pathlib import Path

import numpy as np
import pytest

from parallel_eplus.learning.model_based.control.mpc import MPC
from parallel_eplus.learning.model_based.control.saved_planner import PlannerOptions, planner_file
from parallel_eplus.learning.model_based.runtime.features import step_times
from parallel_eplus.learning.model_based.runtime.guard import GuardState, discomfort
from parallel_eplus.learning.model_based.runtime.planner import _follow

ROOT = Path(__file__).resolve().parents[1]
OFFICE = ROOT / "results/model-based/office-small/runs/office-small-mpc-seed0/planner"
JULY = dt.datetime(2013, 7, 8, 10, 0)  # a Monday morning: the office's band applies


def office(options: str) -> MPC:
    return PlannerOptions.parse(f"comfort_reference=baseline,{options}").apply(MPC.load(planner_file(OFFICE)))


def observation(zone_c: float, outdoor_c: float = 30.0) -> np.ndarray:
    return np.array([[outdoor_c, *[zone_c] * 5, 3000.0, 0.0, 0.0, 0.5]], np.float32)


def own_first(mpc: MPC, info: dict, a_last: np.ndarray) -> np.ndarray:
    """The own plan's first action as a candidate plays it."""
    reference = mpc.baseline_plan([info], mpc.future([info])[2], a_last)
    return _follow(a_last, reference, mpc.settings.max_increment, *mpc.support)[:, 0]


def test_where_the_band_applies_each_thermostat_conditions_at_least_as_much_as_its_own_plan_or_follows_it():
    """Cooling (action 0) no higher and heating (action 1) no lower than the own plan's at every step the band
    applies (`at_least_baseline`), where without it the search raises the cooling setpoint past it; with `own`, both
    follow the own plan; refused without the own plan, or for another value."""
    a_last = np.array([[0.5, -0.5]], np.float32)
    beyond = {}
    for option in ("band_thermostats=free", "band_thermostats=at_least_baseline", "band_thermostats=baseline"):
        mpc = office(option)
        beyond[option] = 0.0
        for month, outdoor, zone in ((4, 15.0, 22.0), (7, 30.0, 23.5)):
            for hour in range(24):
                info = {"time": dt.datetime(2013, month, 8, hour, 0), "weather": "CA"}
                assert mpc.future([info])[1][0, 0] == 1.0  # comfort_hours=all: the band applies at every step
                own = own_first(mpc, info, a_last)
                action = mpc.act(observation(zone, outdoor), [info], a_last)
                beyond[option] = max(beyond[option], float(action[0, 0] - own[0, 0]), float(own[0, 1] - action[0, 1]))
                if option.endswith("=own"):
                    np.testing.assert_allclose(action, own, atol=1e-6)
    assert beyond["band_thermostats=at_least_baseline"] <= 1e-6 < beyond["band_thermostats=free"]
    with pytest.raises(ValueError, match="comfort_reference=baseline"):
        PlannerOptions.parse("band_thermostats=baseline").apply(MPC.load(planner_file(OFFICE)))
    with pytest.raises(ValueError, match="band_thermostats"):
        PlannerOptions.parse("band_thermostats=some")


def test_the_guard_plays_the_own_plan_after_a_move_off_it_ends_in_discomfort_the_model_did_not_predict():
    """A worker whose planner left the own plan, and whose zones then end the step far beyond their bounds (30 C
    where the model predicted the own plan's step inside them), plays the own plan for `guard_steps` steps, then
    plans again; a step that ends as predicted trips nothing."""
    mpc = office("guard_k=0.1,guard_steps=3")
    a_last = np.array([[0.5, -0.5]], np.float32)
    info = {"time": JULY, "weather": "CA"}
    action = mpc.act(observation(23.0), [info], a_last)
    assert not np.allclose(action, own_first(mpc, info, a_last), atol=1e-3)  # the search left the own plan
    assert mpc.guard.states[0].since_left == 0 and mpc.guard.states[0].expected_k is not None
    played = []
    for step in range(1, 6):
        info = {"time": JULY + dt.timedelta(minutes=mpc.step_minutes * step), "weather": "CA"}
        hot = 30.0 if step == 1 else 23.0  # the step after the move ends hot; the rest as the model expects
        action = mpc.act(observation(hot), [info], a_last)
        played.append(bool(np.allclose(action, own_first(mpc, info, a_last), atol=1e-6)))
    assert mpc.guard.trips == 1
    assert played[:3] == [True, True, True] and not all(played[3:])  # held for 3 steps, then planning again
    mpc.reset(0)
    assert mpc.guard.states[0] == GuardState()


def test_the_guard_counts_discomfort_from_the_thermostat_s_setpoint_as_the_score_does():
    """The calendar's bounds are widened by the spec's tolerance; the guard takes it off again (occupied discomfort,
    the score, counts from the setpoint itself), only where the band applies; a served request's `guard` that is
    not the last answer's is refused."""
    bounds = np.array([[[20.8, 24.2], [20.8, 24.2]]], np.float32)  # 21-24 C widened by 0.2 K
    temps = np.array([[24.5, 20.5]], np.float32)
    assert discomfort(temps, bounds, np.array([1.0]), 0.2) == pytest.approx(0.5 + 0.5)
    assert discomfort(temps, bounds, np.array([0.0]), 0.2) == 0.0
    assert GuardState.of({"hold": 2, "since_left": 0, "expected_k": 0.1}) == GuardState(2, 0, 0.1)
    for bad in ({"hold": -1}, {"hold": 1.5}, {"expected_k": float("nan")}, {"other": 1}, [1, 2]):
        with pytest.raises(ValueError, match="guard|hold|expected_k"):
            GuardState.of(bad)


@pytest.mark.slow
def test_the_served_planner_carries_the_guard_in_its_answers_and_acts_as_the_in_process_one(tmp_path, no_leaks):
    """Exported with `guard_k`, the stateless server returns the guard's state in each
    answer; sent back with the next request (as `plan` is), its setpoints equal the in-process planner's step by
    step, through a move off the own plan, a hot step that trips the guard and the steps it holds."""
    from parallel_eplus.buildings.weather.forecast import WEATHER
    from parallel_eplus.deploy.export.policy import export
    from parallel_eplus.deploy.serve.contract import Contract, InputError
    from parallel_eplus.deploy.serve.planner_runtime import PlannerRuntime

    options = "guard_k=0.1,guard_steps=2"
    office(options).save(tmp_path / "planner" / "planner.pt")
    export(tmp_path / "planner", tmp_path / "served", record_days=1, workers=1)
    contract = Contract.read(tmp_path / "served")
    assert contract.data["planner"]["settings"]["guard_k"] == 0.1 and contract.data["guard"]["required"] is False
    data = contract.data  # its fallback off: a 30 C zone is far from the data, and the fallback is not this test's
    runtime = PlannerRuntime(
        tmp_path / "served",
        Contract(
            dict(
                data,
                fallback=dict(
                    data["fallback"],
                    max_spread_k=float("inf"),
                    max_input_z=float("inf"),
                    max_forecast_gap_c=None,
                    max_step_spread_k=None,
                ),
            )
        ),
    )
    mpc = office(options)
    a_last = np.array([[0.5, -0.5]], np.float32)
    physical = mpc.action_low + (a_last[0] + 1) / 2 * (mpc.action_high - mpc.action_low)
    names = [o["name"] for o in contract.outputs]
    sensors = [i["name"] for i in contract.data["inputs"]]
    plan = guard = None
    for step, zone_c in enumerate((23.0, 30.0, 23.0, 23.0, 23.0)):
        when = JULY + dt.timedelta(minutes=mpc.step_minutes * step)
        truth = mpc.forecasts("CA").file.truth(step_times(when, mpc.step_minutes, mpc.settings.horizon))
        obs = observation(zone_c, float(truth[0, 0]))
        body = {"time": when.isoformat(), "sensors": dict(zip(sensors, map(float, obs[0]), strict=True)),
                "last_setpoints": dict(zip(names, map(float, physical), strict=True)), "plan": plan, "guard": guard,
                "forecast": {n: truth[:, i].tolist() for i, n in enumerate(WEATHER)}}  # fmt: skip
        answer = runtime.act(body)
        plan, guard = answer["plan"], answer["guard"]
        expected = mpc.action_low + (mpc.act(obs, [{"time": when, "weather": "CA"}], a_last)[0] + 1) / 2 * (
            mpc.action_high - mpc.action_low
        )
        served = np.array([answer["setpoints"][n]["value"] for n in names])
        np.testing.assert_allclose(served, expected, atol=1e-5)
        assert guard == mpc.guard.states[0].as_dict()
    assert mpc.guard.trips == 1 and guard["since_left"] < 3  # tripped, held, and left the own plan again
    with pytest.raises(InputError, match="guard"):
        runtime.act(dict(body, guard={"hold": "two"}))


def test_band_lead_holds_the_thermostats_to_their_own_plan_that_many_steps_before_the_band_starts():
    """With `band_lead`, each step whose band applies within the next `band_lead` steps follows the own plan, as the
    band's own steps do; steps before that are the search's (the office's night, before its morning); a negative lead
    is refused."""
    a_last = np.array([[0.5, -0.5]], np.float32)
    lead = 6
    for option, led in ((f"band_lead={lead}", True), ("band_lead=0", False)):
        mpc = office(f"comfort_hours=occupied,band_thermostats=baseline,{option}")
        ahead_only = []  # the steps before the band with it within the lead: (followed the own plan)
        for minutes in range(3 * 60, 10 * 60, int(mpc.step_minutes)):
            info = {"time": JULY.replace(hour=0) + dt.timedelta(minutes=minutes), "weather": "CA"}
            applies = mpc.future([info])[1][0]
            if applies[0] == 0 and applies[: lead + 1].any():
                own = own_first(mpc, info, a_last)
                ahead_only.append(bool(np.allclose(mpc.act(observation(22.0, 20.0), [info], a_last), own, atol=1e-6)))
        assert ahead_only, "the office's morning has steps within the lead of its band"
        assert all(ahead_only) if led else not all(ahead_only)
    with pytest.raises(ValueError, match="band_lead"):
        PlannerOptions.parse("band_lead=-1")


def test_own_margin_holds_each_thermostat_that_far_inside_its_own_setpoint_in_process_and_served(tmp_path, no_leaks):
    """With `band_thermostats=baseline` and `baseline_margin`, a July morning's cooling setpoint is its own less the
    margin and
    its heating setpoint its own plus the margin, in K; the served planner sets the same; refused outside [0, 1] K
    or without the own plan."""
    from parallel_eplus.buildings.weather.forecast import WEATHER
    from parallel_eplus.deploy.export.policy import export
    from parallel_eplus.deploy.serve.contract import Contract
    from parallel_eplus.deploy.serve.planner_runtime import PlannerRuntime

    margin, info, obs = 0.05, {"time": JULY, "weather": "CA"}, observation(23.5, 25.0)
    at_own = office("band_thermostats=baseline")
    a_last = at_own.baseline_plan([info], at_own.future([info])[2], np.zeros((1, 2), np.float32))[:, 0]  # on it

    def physical(mpc: MPC, action: np.ndarray) -> np.ndarray:
        return mpc.action_low + (action[0] + 1) / 2 * (mpc.action_high - mpc.action_low)

    inside = office(f"band_thermostats=baseline,baseline_margin={margin}")
    own, held = (physical(m, m.act(obs, [info], a_last)) for m in (at_own, inside))
    np.testing.assert_allclose(own, physical(at_own, a_last), atol=1e-4)  # cooling (0), heating (1) at their own
    np.testing.assert_allclose(held - own, [-margin, margin], atol=1e-4)

    inside.save(tmp_path / "planner" / "planner.pt")
    export(tmp_path / "planner", tmp_path / "served", record_days=1, workers=1)
    data = Contract.read(tmp_path / "served").data  # its fallback off: this test is the margin's
    assert data["planner"]["settings"]["baseline_margin"] == margin
    runtime = PlannerRuntime(
        tmp_path / "served",
        Contract(
            dict(
                data,
                fallback=dict(
                    data["fallback"],
                    max_spread_k=float("inf"),
                    max_input_z=float("inf"),
                    max_forecast_gap_c=None,
                    max_step_spread_k=None,
                ),
            )
        ),
    )
    truth = inside.forecasts("CA").file.truth(step_times(JULY, inside.step_minutes, inside.settings.horizon))
    names, sensors = [o["name"] for o in data["outputs"]], [i["name"] for i in data["inputs"]]
    answer = runtime.act({"time": JULY.isoformat(), "sensors": dict(zip(sensors, map(float, obs[0]), strict=True)),
                          "last_setpoints": dict(zip(names, map(float, physical(inside, a_last)), strict=True)),
                          "forecast": {n: truth[:, i].tolist() for i, n in enumerate(WEATHER)}})  # fmt: skip
    np.testing.assert_allclose([answer["setpoints"][n]["value"] for n in names], held, atol=1e-4)
    for bad in ("baseline_margin=-0.1", "baseline_margin=2"):
        with pytest.raises(ValueError, match="baseline_margin"):
            PlannerOptions.parse(bad)
    with pytest.raises(ValueError, match="comfort_reference=baseline"):
        PlannerOptions.parse("baseline_margin=0.1").apply(MPC.load(planner_file(OFFICE)))
