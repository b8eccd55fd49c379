"""The evaluation sweep and plots on a short sweep (2-day episodes, 2 weathers)."""

from __future__ import annotations

import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from parallel_eplus.evaluation.controllers import BASELINE_LABEL, RBC_LABEL, Controller, policy_controller
from parallel_eplus.evaluation.redraw import plot_path
from parallel_eplus.evaluation.results import write_results
from parallel_eplus.evaluation.sweep import run_sweep
from parallel_eplus.runs.policy_files import _saved_policy
from parallel_eplus.training.config import TrainConfig, TRPOSettings
from parallel_eplus.training.train import train

REPO = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def policy(tmp_path_factory):
    """A briefly trained policy (one small TRPO update on real EnergyPlus)."""
    root = tmp_path_factory.mktemp("policy")
    cfg = TrainConfig(
        workers=2, weathers=["CA"], run_days=1, timesteps=192, batch_size=192, run_name="brief",
        runs_dir=str(root / "runs"), tensorboard_dir=str(root / "tb"),
    )  # fmt: skip
    return train(cfg, progress=False)


def is_png(path) -> bool:
    return path.is_file() and path.stat().st_size > 1000 and path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


@pytest.mark.slow
def test_sweep_writes_table_and_figures(tmp_path, policy, no_leaks):
    controllers = [Controller(BASELINE_LABEL, "baseline"), Controller(RBC_LABEL, "rbc"), policy_controller(str(policy))]
    assert controllers[2].label == "TRPO (CA)"
    df = run_sweep(controllers, ["CA", "VA"], run_days=2, workers=2, out_dir=tmp_path, progress=False)
    files = write_results(df, tmp_path)

    results = pd.read_csv(tmp_path / "results.csv")
    assert list(zip(results.controller, results.weather, strict=True)) == [
        (c, w) for c in (BASELINE_LABEL, RBC_LABEL, "TRPO (CA)") for w in ("CA", "VA")
    ]
    for col in ("reward_mean", "power_kw", "it_power_kw", "hvac_power_kw", "west_temp_std", "east_temp_max"):
        assert col in results.columns and results[col].notna().all()
    assert (results.power_kw > 0).all() and (results.it_power_kw > 0).all()
    assert results.in_band_pct.between(0, 100).all()
    assert (results.steps == 2 * 96).all()
    base = results[results.controller == BASELINE_LABEL]
    assert (base.in_band_pct > 95).all()  # the built-in controller holds its 23 C setpoint
    # Rewards come from the same function for every controller.
    assert np.isfinite(results.reward_mean).all()

    md = (tmp_path / "results.md").read_text()
    assert "| **Average** |" in md and "TRPO (CA): power (kW)" in md and "%" in md
    # BOPTEST's figures ([kpis]): the cooling's electricity per m², each over the built-in's on the same weather
    assert "BOPTEST's figures" in md and "HVAC energy (kWh/m²)" in md
    assert np.allclose(results.hvac_energy_kwh_m2 * results.floor_area_m2, results.hvac_energy_kwh)
    assert np.allclose(results[results.controller == BASELINE_LABEL].hvac_energy_kwh_vs_builtin, 1.0)
    for name in ("temperatures.png", "power.png", "west_zone_histogram.png"):
        assert is_png(tmp_path / name), name
    assert len(files) == 5


@pytest.mark.slow
def test_a_sweep_through_ray_tasks_gives_the_local_sweeps_table_and_figures_and_a_bar_moving_within_episodes(
    tmp_path, policy, no_leaks, monkeypatch
):
    """Each episode a Ray task with the policy shipped to it: the same rows, the episode files brought back. And each
    task reports its steps as it goes (every PROGRESS_STEPS), so the bar of a year-long evaluation moves before its
    first episode ends, and ends at every step counted once: here a month (2,880 steps, two reports), the driver
    reading them every 0.2 s rather than every POLL_S (a year took 50 s). Both on the tests' shared Ray (conftest;
    a sweep that starts and ends its own Ray: test_ctrl_c_in_a_ray_evaluation...)."""
    pytest.importorskip("ray")
    from parallel_eplus.evaluation import ray_sweep
    from parallel_eplus.evaluation.sweep import _job_config

    controllers = [Controller(BASELINE_LABEL, "baseline"), policy_controller(str(policy))]
    local = run_sweep(controllers, ["CA", "FL"], 1, 2, tmp_path / "local", progress=False)
    swept = run_sweep(controllers, ["CA", "FL"], 1, 2, tmp_path / "ray", progress=False, backend="ray")
    pd.testing.assert_frame_equal(swept.drop(columns="episode_dir"), local.drop(columns="episode_dir"))
    assert all(str(d).startswith(str(tmp_path / "ray")) for d in swept.episode_dir)
    write_results(swept, tmp_path / "ray")  # the figures read the episode files the tasks returned
    assert is_png(tmp_path / "ray" / "west_zone_histogram.png")

    events: list[tuple[str, int]] = []

    class Bar:  # what the sweep's tqdm is told
        n = 0

        def update(self, k: int) -> None:
            self.n += k
            events.append(("update", self.n))

        def set_postfix(self, **_) -> None:
            events.append(("episode ended", self.n))

    days = 30
    assert days * 96 > 2 * ray_sweep.PROGRESS_STEPS
    monkeypatch.setattr(ray_sweep, "POLL_S", 0.2)
    base = controllers[0]
    job = (base, _job_config(base, "CA", None, days, None, tmp_path / "bar"))
    rows, _ = ray_sweep.run_jobs([job], 1, None, Bar(), 900)
    first_end = events.index(next(e for e in events if e[0] == "episode ended"))
    assert any(0 < n < days * 96 for kind, n in events[:first_end] if kind == "update")  # part of the month
    assert events[-1][1] == rows[0]["steps"] == days * 96


@pytest.mark.slow
def test_plot_run_and_episode(tmp_path, policy):
    run_dir = policy.parent
    assert is_png(plot_path(run_dir))
    episode = sorted((run_dir / "episodes").glob("worker-*/episode-*"))[-1]
    assert is_png(plot_path(episode))


@pytest.mark.slow
def test_bad_input_fails_before_anything_runs(tmp_path, caplog):
    """The command's exit code and its one error line, in process (a fresh interpreter costs its imports each time;
    the process's own exit code and stderr: tests/faults/test_run_files.py)."""
    from parallel_eplus.cli import main

    def cli(*args) -> tuple[int, str]:
        caplog.clear()
        return main(["evaluate", *args, "--out", str(tmp_path)]), caplog.text

    code, err = cli("--baseline", "--weathers", "CA,XX")
    assert code == 2 and "unknown weather 'XX'" in err
    code, err = cli("--policy", str(tmp_path / "missing.zip"))
    assert code == 2 and "policy not found" in err
    code, err = cli("--rbc-targets", "22.7,warm")
    assert code == 2 and "--rbc-targets takes zone temperatures" in err
    assert not any(tmp_path.iterdir())


@pytest.mark.slow
@pytest.mark.parametrize("schedule", [False, True])
def test_policy_with_extra_features_is_evaluated_with_them(tmp_path, no_leaks, schedule):
    cfg = TrainConfig(
        workers=1, weathers=["CO"], run_days=1, timesteps=96, batch_size=96, run_name="clock", time_features=True,
        schedule_features=schedule, runs_dir=str(tmp_path / "runs"), tensorboard_dir=str(tmp_path / "tb"),
    )  # fmt: skip
    controller = policy_controller(str(train(cfg, progress=False)))
    assert controller.time_features and controller.schedule_features == schedule
    df = run_sweep([controller], ["CO"], run_days=1, workers=1, out_dir=tmp_path / "eval", progress=False)
    assert df.steps.tolist() == [96] and df.power_kw.gt(0).all()


@pytest.mark.slow
def test_rule_based_controller_holds_the_target_it_is_given(tmp_path, no_leaks):
    controllers = [Controller(f"RBC {t}", "rbc", rbc_target_c=t) for t in (22.7, 23.7)]
    df = run_sweep(controllers, ["CO"], 3, 2, tmp_path, progress=False).set_index("controller")
    cold, warm = df.loc["RBC 22.7"], df.loc["RBC 23.7"]
    for zone in ("west", "east"):
        assert warm[f"{zone}_temp_mean"] - cold[f"{zone}_temp_mean"] > 0.6, zone


def test_a_runs_best_and_cloned_policies_are_read_with_the_runs_settings(tmp_path):
    # a committed office run (results/weather/runs/), its policy also kept where --eval-every and
    # --init-from-baseline keep theirs: each reads the run's config.json, not the folder it sits in
    run = tmp_path / "office-run"
    shutil.copytree(REPO / "results/weather/runs/office-small-base-seed0", run)
    for folder in ("best", "cloned"):
        (run / folder).mkdir()
        for name in ("model.zip", "vecnormalize.npz"):
            shutil.copy(run / name, run / folder / name)
        controller = policy_controller(str(run / folder / "model.zip"))
        assert (controller.building, controller.run) == ("office-small", "office-small-base-seed0"), folder
        assert controller.forecast_hours == 0 and controller.time_features


@pytest.mark.slow
@pytest.mark.parametrize("space", ["action", "demand"])
def test_residual_policy_is_evaluated_as_a_correction_of_the_rule_based_controller(tmp_path, no_leaks, space):
    cfg = TrainConfig(
        workers=1, weathers=["CO"], run_days=1, timesteps=96, batch_size=96, run_name="residual",
        time_features=True, residual_scale=0.1, residual_space=space, rbc_target_c=23.0,
        runs_dir=str(tmp_path / "runs"), tensorboard_dir=str(tmp_path / "tb"), trpo=TRPOSettings(log_std_init=-1.5),
    )  # fmt: skip
    final = train(cfg, progress=False)
    # The exploration starts where asked (one small TRPO update moves it only a little).
    assert _saved_policy(final).log_std.detach().numpy() == pytest.approx(-1.5, abs=0.1)
    controller = policy_controller(str(final))
    assert (controller.residual_scale, controller.residual_space, controller.rbc_target_c) == (0.1, space, 23.0)
    assert controller.label == "TRPO+RBC (CO)"
    df = run_sweep([controller], ["CO"], run_days=1, workers=1, out_dir=tmp_path / "eval", progress=False)
    steps = pd.read_parquet(f"{df.episode_dir[0]}/steps.parquet")
    # Alone, a barely trained policy's mean action is mid-range (25 C supply air); as a correction it
    # stays within 0.1 of the half-range (1.5 C), or 0.1 kg/s of demand, of the controller's: cold supply air.
    assert steps.west_setpoint_c.median() < 15 and steps.east_setpoint_c.median() < 15


@pytest.mark.slow
def test_online_protocol_keeps_learning_on_each_weather_and_leaves_the_model_alone(tmp_path, policy, no_leaks):
    final = policy  # the module's briefly trained policy: the online copies must leave its files as they were
    before = final.read_bytes(), (final.parent / "vecnormalize.npz").read_bytes()
    from parallel_eplus.cli import main

    out = tmp_path / "eval"
    args = ["evaluate", "--policy", str(final), "--online", "--online-batch", "32", "--weathers", "CA,IL",
            "--run-days", "1", "--workers", "2", "--out", str(out), "--quiet"]  # fmt: skip
    assert main(args) == 0  # in process: the command's process boundary is tests/faults/test_run_files.py's
    df = pd.read_csv(out / "results.csv")
    assert sorted(df["controller"].unique()) == ["TRPO (CA)", "TRPO (CA), online"]
    online = df[df["controller"] == "TRPO (CA), online"]
    assert sorted(online["weather"]) == ["CA", "IL"] and (online["steps"] == 96).all()
    assert online["reward_mean"].notna().all()
    assert (final.read_bytes(), (final.parent / "vecnormalize.npz").read_bytes()) == before
    assert not list(Path(tempfile.gettempdir()).glob("SB3-*"))  # the learning copies wrote no SB3 log folder


def test_ctrl_c_in_a_ray_evaluation_leaves_no_process_and_no_episode_folder(tmp_path, no_leaks):
    """Ctrl-C in `evaluate --backend ray`: the running tasks are cancelled and Ray's workers killed outright, so they
    cannot remove their episodes' scratch folders; the evaluation removes them (their owners are gone)."""
    pytest.importorskip("ray")
    import signal
    import time

    from parallel_eplus.engine.pipes.leftovers import owner_alive

    def scratch() -> set[Path]:
        return set(Path(tempfile.gettempdir()).glob("parallel-eplus-eval-*"))

    before = scratch()
    args = ["evaluate", "--baseline", "--weathers", "CA,FL", "--run-days", "365", "--workers", "2", "--backend", "ray",
            "--out", str(tmp_path), "--quiet"]  # fmt: skip
    proc = subprocess.Popen([sys.executable, "-m", "parallel_eplus.cli", *args], stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT, text=True)  # fmt: skip
    deadline = time.monotonic() + 180
    while len(scratch() - before) < 2:  # both episodes have started
        assert proc.poll() is None, proc.stdout.read()
        assert time.monotonic() < deadline
        time.sleep(0.2)
    time.sleep(1)  # and are under way
    proc.send_signal(signal.SIGINT)
    out, _ = proc.communicate(timeout=180)
    assert proc.returncode != 0 and "interrupted" in out
    assert [d for d in scratch() - before if owner_alive(d) is False] == []


def test_resume_runs_only_the_episodes_an_interrupted_sweep_did_not_finish(tmp_path, no_leaks):
    controllers = [Controller(BASELINE_LABEL, "baseline"), Controller(RBC_LABEL, "rbc")]
    first = run_sweep(controllers, ["CA", "FL"], 1, 2, tmp_path, progress=False)
    cut = Path(first.set_index(["controller", "weather"]).loc[(RBC_LABEL, "FL"), "episode_dir"])
    summary = cut / "summary.json"  # as a stopped episode leaves it: its partial record, not complete
    summary.write_text(summary.read_text().replace('"complete": true', '"complete": false'))

    again = run_sweep(controllers, ["CA", "FL"], 1, 2, tmp_path, progress=False, resume=True)
    dirs = dict(zip(zip(again.controller, again.weather, strict=True), again.episode_dir, strict=True))
    assert [k for k in dirs if dirs[k] not in set(first.episode_dir)] == [(RBC_LABEL, "FL")]
    assert Path(dirs[(RBC_LABEL, "FL")]).parent == cut.parent and Path(dirs[(RBC_LABEL, "FL")]) != cut
    pd.testing.assert_series_equal(first.energy_kwh, again.energy_kwh)  # the same table, rerun episode included

    longer = run_sweep(controllers[:1], ["CA"], 2, 1, tmp_path, progress=False, resume=True)
    assert longer.episode_dir[0] not in set(first.episode_dir)  # another length is another episode


def test_resume_takes_an_episode_only_for_its_own_weather_length_building_and_test_period():
    from parallel_eplus.engine.config import SimulationConfig
    from parallel_eplus.evaluation.resume import same_job

    cfg = SimulationConfig(weather="CO", building="/copy-1/specs/office-medium.toml", run_days=21, start_day=40,
                           warmup_days=7)  # fmt: skip
    summary = {"complete": True, "weather": "CO", "run_days": 21, "building": "/copy-2/specs/office-medium.toml",
               "warmup_days": 7, "period_start": "2017-02-16 00:10:00"}  # fmt: skip
    assert same_job(summary, cfg)  # day 47: the period's first scored day; another code copy's path, same spec
    for change in ({"period_start": "2017-07-01 00:10:00"}, {"building": "/x/office-small.toml"}, {"weather": "FL"},
                   {"complete": False}, {"warmup_days": 0}, {"run_days": 365}):  # fmt: skip
        assert not same_job({**summary, **change}, cfg), change
