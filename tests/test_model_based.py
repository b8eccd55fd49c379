"""`train --algorithm mpc` on real short episodes: the model, the planner, the distilled policy, a killed worker.

One small run (2 workers, CA and FL, 2-day episodes: the building's own controls recorded, a day of exploration,
then the planner, evaluated every 384 steps) serves the first three tests and the evaluation's; the others run their
own.
"""

from __future__ import annotations

import datetime as dt
import json
import signal
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import torch as th
from sb3_contrib import TRPO

from parallel_eplus.buildings.building import load_building
from parallel_eplus.buildings.resources import builtin_specs
from parallel_eplus.errors import EnergyPlusError
from parallel_eplus.evaluation.controllers import Controller
from parallel_eplus.evaluation.sweep import run_sweep
from parallel_eplus.learning.model_based.control.mpc import MPC
from parallel_eplus.learning.model_based.control.saved_planner import planner_controller
from parallel_eplus.learning.model_based.model.dataset import ORIGINS, Transitions
from parallel_eplus.learning.model_based.settings import MPCSettings
from parallel_eplus.runs.policy_files import load_policy
from parallel_eplus.training.config import ComfortConstraint, TrainConfig
from parallel_eplus.training.train import train

from .faults.strikes import strike_after_step


def mpc_config(root: Path, name: str, **overrides) -> TrainConfig:
    settings = overrides.pop("mpc", MPCSettings(explore_steps=192, refit_every=192, epochs=20, candidates=128))
    base = dict(
        algorithm="mpc", workers=2, weathers=["CA", "FL"], run_days=2, timesteps=768, checkpoint_every=384,
        run_name=name, runs_dir=str(root / "runs"), tensorboard_dir=str(root / "tb"), mpc=settings,
        comfort=ComfortConstraint(target_pct=99.0),
    )  # fmt: skip
    base.update(overrides)
    return TrainConfig(**base)


@pytest.fixture(scope="module")
def mpc_run(tmp_path_factory) -> Path:
    """The small run, evaluated as it trains (`--eval-every 384`: the frozen planner, saved and loaded by `evaluate`'s
    own code, so the run's own planner and data are as without it)."""
    from parallel_eplus.training.eval_target import EvalSettings

    root = tmp_path_factory.mktemp("mpc")
    evaluation = EvalSettings(every=384, days=1, target="in_band_pct>=50")
    final = train(mpc_config(root, "small", evaluation=evaluation), progress=False)
    assert final == root / "runs" / "small" / "model.zip"
    return final.parent


@pytest.mark.slow
def test_the_model_beats_persistence_on_held_out_steps(mpc_run, no_leaks):
    mpc = MPC.load(mpc_run / "planner" / "planner.pt")
    data = Transitions.load(mpc_run / "transitions.npz", mpc.layout)
    held = data.held_out(24)  # quarter days (a 2-day episode has too few whole days to hold out)
    assert 0 < held.sum() < len(data)
    errors = mpc.model.errors(data, held, 4)
    for name in mpc.layout.state_names:  # both zones and the power
        assert errors[f"{name}/1_step_model"] < errors[f"{name}/1_step_persistence"], (name, errors)
    saved = json.loads((mpc_run / "model_error.json").read_text())  # what the run reported (TensorBoard too)
    assert "west_temp_c/1_step_model" in saved


class Constant(Controller):
    def make(self, building=None):
        return lambda obs, info: np.zeros(4, np.float32)  # mid-range setpoints (25 °C) and fans


@pytest.mark.slow
def test_the_planner_keeps_a_two_day_episode_in_band_where_a_constant_action_does_not(mpc_run, tmp_path, no_leaks):
    th.set_num_threads(1)
    planner = planner_controller(f"{mpc_run / 'planner'}=Planner")
    assert planner.kind == "planner" and planner.run == "small"
    table = run_sweep([planner, Constant("Constant", "policy")], ["CA"], 2, 2, tmp_path / "ev", progress=False)
    in_band = dict(zip(table["controller"], table["in_band_pct"], strict=True))
    assert in_band["Planner"] >= 95.0, in_band
    assert in_band["Constant"] < 50.0, in_band


@pytest.mark.slow
def test_the_distilled_policy_tracks_the_planners_actions(mpc_run):
    saved = sorted((mpc_run / "checkpoints").glob("mpc_*_steps.npz"), key=lambda p: int(p.stem.split("_")[1]))[-1]
    with np.load(saved) as z:
        obs, planned = z["policy_obs"], z["policy_act"]
    assert len(obs) >= 500  # every planner step of both workers
    act = load_policy(mpc_run / "model.zip")
    distilled = act(obs)
    mse = ((distilled - planned) ** 2).mean(0)
    var = planned.var(0)  # what the best constant action would score
    # Every action better than a constant; the four together within 0.8 of its RMSE (a fit explaining > 36 % of the
    # planner's variation). Per action at 0.8, one of four landed at 0.84 on CI: workers' timing varies the data.
    assert np.all(mse < var), (mse, var)
    assert mse.sum() < 0.64 * var.sum(), (mse, var)


@pytest.mark.slow
def test_a_worker_killed_mid_plan_ends_the_run_with_a_checkpoint_and_it_resumes(tmp_path, monkeypatch, no_leaks):
    settings = MPCSettings(explore_steps=0, refit_every=96, epochs=10, candidates=64, record_days=1)
    cfg = mpc_config(tmp_path, "cut", run_days=1, weathers=["CA"], timesteps=10_000, max_restarts=0, mpc=settings)
    hit = strike_after_step(monkeypatch, signal.SIGKILL, worker="0", episode=1, step=40)
    with pytest.raises(EnergyPlusError):
        train(cfg, progress=False)
    assert hit
    run = tmp_path / "runs" / "cut"
    saved = list((run / "checkpoints").glob("mpc_*_steps.pt"))
    assert len(saved) == 1 and (run / "checkpoints" / saved[0].with_suffix(".npz").name).is_file()
    assert json.loads((run / "status.json").read_text())["state"] == "failed"
    monkeypatch.undo()
    steps = int(saved[0].stem.split("_")[1])
    assert 0 < steps < 96
    resumed = mpc_config(tmp_path, "cut", timesteps=steps + 20)
    final = train(resumed, resume=run, progress=False)
    assert final == run / "model.zip" and (run / "planner" / "planner.pt").is_file()
    assert json.loads((run / "status.json").read_text())["state"] == "finished"


@pytest.mark.slow
def test_eval_every_measures_the_frozen_planner_keeps_the_best_and_records_the_target(mpc_run):
    import pandas as pd

    from parallel_eplus.runs.run_files import BEST_DIR, EVALUATIONS_FILE, TARGET_FILE

    run = mpc_run  # evaluated every 384 steps, target in_band_pct>=50
    table = pd.read_csv(run / EVALUATIONS_FILE)
    assert sorted(set(table.timesteps)) == [384, 768]
    assert set(table.weather) == {"all", "CA", "FL"}
    assert (run / BEST_DIR / "planner" / "planner.pt").is_file()
    best = json.loads((run / BEST_DIR / "evaluation.json").read_text())
    means = table[table.weather == "all"].set_index("timesteps")
    assert best["timesteps"] == means["score"].idxmax()
    target = json.loads((run / TARGET_FILE).read_text())
    met = means[means["in_band_pct"] >= 50]
    assert target["timesteps"] == met.index.min()  # the planner holds the band (the test above): met at once


@pytest.mark.parametrize("name", sorted(builtin_specs()))
def test_the_models_state_reads_only_what_the_agent_observes_and_its_parts_sum_to_the_energy(name):
    """The office's HVAC gas is a meter the agent does not observe: splitting on it read past the observation."""
    from parallel_eplus.learning.model_based.runtime.layout import Layout

    building = load_building(name)
    layout = Layout.of(building, n_exogenous=5)
    obs = np.random.default_rng(0).uniform(1e3, 1e5, (3, len(building.observed))).astype(np.float32)
    assert layout.sensors == tuple(s.name for s in building.observed)
    state = layout.state(obs)
    assert state.shape == (3, layout.n_state)
    energy = obs[:, [layout.sensors.index(e) for e in layout.energy]].sum(1)
    np.testing.assert_allclose(state[:, len(layout.temperatures) :].sum(1), energy, rtol=1e-5)


@pytest.mark.slow
def test_a_building_with_hidden_sensors_and_an_occupancy_calendar_plans_too(tmp_path, no_leaks):
    """The office: thermostat schedules and its HVAC gas are sensors the agent does not observe, and its band
    applies when occupied; a first run failed on its recorded controls before any step."""
    settings = MPCSettings(explore_steps=48, refit_every=96, epochs=5, candidates=32, comfort_hours="occupied",
                           comfort_reference="baseline", comfort_level="baseline")  # fmt: skip
    cfg = mpc_config(tmp_path, "office", building="office-small", weathers=["CA"], run_days=1, timesteps=192,
                     checkpoint_every=96, mpc=settings, comfort=ComfortConstraint(target_pct=97.5),
                     objective="cost")  # fmt: skip
    final = train(cfg, progress=False)
    mpc = MPC.load(final.parent / "planner" / "planner.pt")
    assert mpc.energy_weights.objective == "cost" and mpc.demand  # the bill, demand charges too, was its objective
    assert mpc.settings.comfort_reference == "baseline" and mpc.comfort_times.occupied_only
    saved = th.load(sorted((final.parent / "checkpoints").glob("mpc_*_steps.pt"))[-1], weights_only=True)
    own = saved["own_level"]["out"]["CA"].numpy()  # the own controls' comfort by date, for the multiplier
    assert len(own) == 366 * 144 and np.all(own[:144] == -1)  # January 1, a holiday: the band did not apply
    recorded = mpc.comfort_times.dated_applies[mpc.comfort_times.dated_applies >= 0]
    assert len(recorded) >= 143 and not recorded.any()  # the recorded day by date (January 1, a holiday)
    assert mpc.layout.state_names[-2:] == ("power_w", "gas_w")  # its gas meter is hidden: no HVAC parts
    assert len(Transitions.load(final.parent / "transitions.npz", mpc.layout)) > 192
    # it plans against each zone's own thermostat bounds as they were at that time of the week (a first version
    # planned against the spec's fixed band, and held 63 % of the occupied steps in the bounds it is scored on)
    times = mpc.comfort_times
    seen = np.flatnonzero(times.bound_seen)
    assert len(seen) >= 96  # the recorded day and the run's own steps
    monday = dt.datetime(2024, 1, 1)  # slot k of the week starts k steps after a Monday's midnight
    at = [monday + dt.timedelta(minutes=float(times.step_minutes * k)) for k in seen]
    bounds = times.bounds(at)  # [T, zones, 2]
    night = np.array([t.hour == 3 for t in at])
    # the edges the share in band counts: the setbacks widened by the thermostat bounds' 0.2 K of tolerance
    np.testing.assert_allclose(bounds[night], np.broadcast_to([15.4, 26.9], bounds[night].shape), atol=0.05)
    assert np.all(bounds[..., 0] < bounds[..., 1])
    unseen = monday + dt.timedelta(minutes=float(times.step_minutes * np.flatnonzero(times.bound_seen == 0)[0]))
    np.testing.assert_allclose(times.bounds([unseen])[0], times.fixed + [-0.2, 0.2])  # nothing seen: the spec's band


@pytest.mark.slow
def test_the_planner_reads_the_thermostats_by_date_across_daylight_saving_time(tmp_path, no_leaks):
    """The office's schedules follow daylight-saving time (from March 12, 2006, its day starts and ends an hour
    earlier on the simulation's standard-time clock); by weekday and time alone, the planner's bounds at either end
    of its day blended both weeks, and it let the zones go an hour early."""
    from parallel_eplus.evaluation.scenarios import Period
    from parallel_eplus.learning.model_based.runtime.calendar import Calendar, ComfortTimes

    march = Period("test", day=64, start_day=65, weekday="Monday", run_days=14, warmup_days=0)  # March 6-19
    df = run_sweep([Controller("Baseline", "baseline")], ["CA"], 14, 1, tmp_path, False, building="office-small",
                   periods={"CA": march})  # fmt: skip
    steps = pd.read_parquet(Path(df["episode_dir"][0]) / "steps.parquet")
    times = list(steps["time"].dt.to_pydatetime())
    low, high = steps["setpoint_htgsetp_sch"].to_numpy(), steps["setpoint_clgsetp_sch"].to_numpy()
    bounds = np.broadcast_to(np.stack([low, high], -1)[:, None, :], (len(times), 5, 2))
    weekday_21h = [
        (t.day, lo) for t, lo in zip(times, low, strict=True) if t.weekday() < 5 and t.hour == 21 and t.minute == 30
    ]
    assert {lo for d, lo in weekday_21h if d < 12} == {21.0} and {lo for d, lo in weekday_21h if d > 12} == {15.6}

    occupied = steps["comfort_applies"].to_numpy(np.float32)
    assert 0 < occupied.mean() < 1
    comfort = ComfortTimes("office-small", 10)
    comfort.learn(times, occupied, bounds)
    np.testing.assert_allclose(comfort.bounds(times), bounds + [-0.2, 0.2], atol=1e-5)  # every step, as recorded
    assert np.all(comfort(times) == 1)  # the planner pays for every step's bounds, setbacks too (BOPTEST's)
    again = ComfortTimes("office-small", 10, occupied_only=True)  # a planner saved and loaded reads the same
    again.load({k: th.as_tensor(v).numpy() for k, v in comfort.state().items()})
    np.testing.assert_allclose(again.bounds(times), comfort.bounds(times))
    np.testing.assert_array_equal(again(times), occupied)  # comfort_hours=occupied: the occupied hours, by date
    served = Calendar.from_arrays(again.settings(), again.state())  # an exported planner's
    np.testing.assert_array_equal(served(times), occupied)
    next_year = [t.replace(year=2007) for t in times]  # other weekdays: the weekly slots, the spec's band unseen
    assert np.all(np.isfinite(again.bounds(next_year)))


@pytest.mark.slow
def test_the_ray_backend_runs_the_planner_too(tmp_path, no_leaks):
    """`train --algorithm mpc --backend ray`: the same loop over Ray's actors (the planner plans for every worker in
    one call, whichever backend steps them)."""
    pytest.importorskip("ray")
    steps = 384  # one-day episodes: the own controls recorded on a day per weather, 96 explored, 288 planned
    cfg = mpc_config(tmp_path, "ray", backend="ray", run_days=1, timesteps=steps, checkpoint_every=192,
                     mpc=MPCSettings(explore_steps=96, refit_every=192, epochs=5, candidates=32))  # fmt: skip
    final = train(cfg, progress=False)
    run = final.parent
    assert final == run / "model.zip" and (run / "planner" / "planner.pt").is_file()
    status = json.loads((run / "status.json").read_text())
    assert status["state"] == "finished" and status["steps"] >= steps, status
    data = Transitions.load(run / "transitions.npz", MPC.load(run / "planner" / "planner.pt").layout)
    assert (data.array("origin") == ORIGINS.index("planner")).sum() >= steps - 96  # both of Ray's workers, planned


@pytest.mark.slow
def test_a_student_trained_through_the_model_sees_the_clock_and_resumes_with_its_starts(tmp_path, no_leaks):
    settings = MPCSettings(explore_steps=96, refit_every=96, epochs=5, candidates=32, dagger_share=0.5,
                           student="gradient", student_updates=20, student_batch=32, student_margin=0.6)  # fmt: skip
    cfg = mpc_config(tmp_path, "grad", run_days=1, timesteps=384, checkpoint_every=192, time_features=True,
                     schedule_features=True, mpc=settings)  # fmt: skip
    final = train(cfg, progress=False)
    run = final.parent
    report = json.loads((run / "distill.json").read_text())
    assert report["student"] == "gradient" and report["starts"] == 384 - 96  # every planner step, both workers
    assert report["margin_c"] == 0.6  # the student's band, not the planner's --comfort-margin
    assert set(report["cost"]) == {"energy", "comfort", "spread", "moves"}
    model = TRPO.load(final, device="cpu")
    assert model.observation_space.shape == (6 + 4 + 5,)  # the sensors, the time's and the IT schedule's features
    saved = sorted((run / "checkpoints").glob("mpc_*_steps.npz"), key=lambda p: int(p.stem.split("_")[1]))[-1]
    with np.load(saved) as z:
        assert len(z["policy_prev"]) == len(z["policy_obs"]) == len(z["policy_time"]) == len(z["policy_weather"])
        assert set(z["policy_weather"]) == {"CA", "FL"}
    resumed = train(mpc_config(tmp_path, "grad", run_days=1, timesteps=480, checkpoint_every=192, time_features=True,
                               schedule_features=True, mpc=settings), resume=run, progress=False)  # fmt: skip
    assert resumed == final
    assert json.loads((run / "distill.json").read_text())["starts"] == 480 - 96  # the saved starts, then the new


@pytest.mark.slow
def test_a_run_too_short_to_plan_ends_with_its_planner_named(tmp_path, monkeypatch, capsys, no_leaks):
    """All its steps explore, so there is no planner step to distil: `train` names the planner, not a policy."""
    from parallel_eplus.cli import main

    args = ["train", "--algorithm", "mpc", "--workers", "1", "--weathers", "CA", "--run-days", "1", "--timesteps",
            "96", "--mpc", "explore_steps=192,epochs=2", "--run-name", "short", "--quiet"]  # fmt: skip
    monkeypatch.chdir(tmp_path)  # runs/ and tensorboard_logs/ land here
    assert main(args) == 0
    out = capsys.readouterr().out
    planner = tmp_path / "runs" / "short" / "planner"
    assert f"planner: {planner}" in out and (planner / "planner.pt").is_file(), out
    assert f"episode records: {tmp_path / 'runs' / 'short' / 'episodes.csv'}" in out
    assert not (tmp_path / "runs" / "short" / "model.zip").exists()
