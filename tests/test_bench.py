"""The benchmark itself, end to end on a tiny size: every measurement runs and the table reads it."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from parallel_eplus.bench import BenchConfig, _physical, format_table, raw_rate, run
from parallel_eplus.bench.boptest import overhead_rows
from parallel_eplus.buildings.datacenter import ACTIONS
from parallel_eplus.engine.config import SimulationConfig
from parallel_eplus.engine.episode import read_steps
from parallel_eplus.engine.simulation import Simulation


@pytest.mark.slow
def test_bench_measures_everything_and_writes_json(tmp_path, no_leaks):
    cfg = BenchConfig(raw_days=1, vector_steps=40, train_steps=128, batch_size=128, workers=2, repeats=1, boptest=True)
    out = tmp_path / "bench.json"
    results = run(cfg, out)
    assert json.loads(out.read_text()) == results
    assert results["env_steps_per_s"] > 0 and results["env_over_raw"] == results["env_s"] / results["raw_s"]
    assert results["alone_s"] > 0 and results["env_over_alone"] == results["env_s"] / results["alone_s"]
    # Two raw runs at once take at least about as long as one (not half: each does a whole run).
    assert results["raw_scaling"] == pytest.approx(results["raw_s"] / results["raw_n_s"])
    assert results["raw_scaling"] > 0  # its value is a figure bench prints, not a test's to judge (a loaded machine)
    for n in ("1", "n"):
        assert results[f"vector_{n}_steps_per_s"] > 0
        assert 0 < results[f"vector_{n}_cores_busy"] <= cfg.workers + 0.5
    assert results["lockstep_n_steps_per_s"] > 0
    assert results["lockstep_scaling"] == pytest.approx(
        results["lockstep_n_steps_per_s"] / (2 * results["vector_1_steps_per_s"])
    )
    assert results["independent_n_steps_per_s"] > 0
    assert results["independent_scaling"] == pytest.approx(
        results["independent_n_steps_per_s"] / (2 * results["vector_1_steps_per_s"])
    )
    for n in ("1", "n"):
        assert results[f"vector_{n}_over_raw"] > 0 and results[f"raw_exploring_{n}_steps_per_s"] > 0
    assert results["million_steps_floor_minutes"] > 0
    assert results["update_s"] > 0 and results["train_steps_per_s"] > 0
    assert results["train_ray_over_local"] == results["train_ray_steps_per_s"] / results["train_steps_per_s"] > 0
    table = format_table(results)
    assert "EnergyPlus alone, EMS holds the action" in table and "pipes only" in table
    assert "2 runs at once" in table and "cores busy" in table and "stepped alone" in table and "lockstep" in table
    assert "Ray backend" in table
    # `bench --boptest`'s row: a day of the data center's 15-minute steps in process, then through `parallel-eplus
    # boptest` (its own process, HTTP on loopback), step by step: each run's ms per step and what the API adds.
    r = results["boptest"]
    assert r["building"] == "datacenter-2zone" and r["step_s"] == 900 and r["steps"] == 95  # the last step left out
    for key in ("energyplus_ms", "api_ms"):
        assert set(r[key]) == {"mean", "p50", "p99"} and all(0 < v < math.inf for v in r[key].values()), r
    assert set(r["added_ms"]) == {"mean", "p50", "p99"} and all(math.isfinite(v) for v in r["added_ms"].values())
    assert r["added_ms"]["mean"] == pytest.approx(r["api_ms"]["mean"] - r["energyplus_ms"]["mean"])
    assert 0 < r["ratio"] < math.inf and len(r["load_average"]) == 2
    assert "POST /advance" in table and "POST /advance" in overhead_rows(r)[0][0] and "p99 +" in overhead_rows(r)[0][1]


def _env_day(tmp_path, actions: np.ndarray, building: str | None = None):
    """One day through the env with these actions; returns its episode directory."""
    sim = Simulation(SimulationConfig(building=building, run_days=1, output_dir=str(tmp_path / "env")))
    try:
        sim.start()
        for a in actions[:, 0]:
            sim.send(a)
            sim.receive()
        return sim.episode_dir
    finally:
        sim.close()


@pytest.mark.parametrize("bridge", ["c", "python"])
def test_raw_replay_is_the_envs_physics_without_the_pipes(tmp_path, no_leaks, bridge, monkeypatch):
    """The floor the benchmark measures against: replaying an env run's actions in raw EnergyPlus gives
    the very same simulation, timestep by timestep (so raw and env do the same work)."""
    from parallel_eplus.engine.eplus_side import native

    if bridge == "python":
        monkeypatch.setattr(native, "bridge_library", lambda: None)
    elif native.bridge_library() is None:
        pytest.skip("no C compiler")
    actions = np.clip(np.random.default_rng(5).normal(size=(96, 1, 4)), -1, 1)
    env_dir = _env_day(tmp_path, actions)
    steps = read_steps(env_dir)
    sent = steps[[e.name for e in ACTIONS]].to_numpy()
    np.testing.assert_allclose(sent, [_physical(a) for a in actions[:, 0]])
    assert raw_rate(BenchConfig(), tmp_path / "raw", actions, energyplus_csv=True) > 0
    env_out = pd.read_csv(env_dir / "eplusout.csv")
    raw_out = pd.read_csv(tmp_path / "raw" / "copy0" / "eplusout.csv")
    assert len(env_out) == 96 and env_out["Date/Time"].equals(raw_out["Date/Time"])
    pd.testing.assert_frame_equal(raw_out, env_out)


def test_bench_runs_a_building_spec(tmp_path, no_leaks):
    """`bench --building`: raw EnergyPlus replays a spec's actions, at its own timestep (10 minutes for the
    CRAC), as its env applied them; the env run and the constant-action raw run are the spec's too."""
    from parallel_eplus.bench.rates import env_run
    from parallel_eplus.bench.raw import raw_seconds
    from parallel_eplus.buildings.building import load_building

    building = load_building("datacenter-crac")
    steps = building.steps_per_day
    assert steps == 144
    actions = np.clip(np.random.default_rng(3).normal(size=(steps, 1, len(building.actions))), -1, 1)
    env_dir = _env_day(tmp_path, actions, "datacenter-crac")
    sent = read_steps(env_dir)[[e.name for e in building.actions]].to_numpy()
    np.testing.assert_allclose(sent, [_physical(a, "datacenter-crac") for a in actions[:, 0]])
    cfg = BenchConfig(building="datacenter-crac", raw_days=1)
    assert raw_rate(cfg, tmp_path / "raw", actions) > 0
    # This model writes no CSV: its output file, every reported value, minus the line with the date it ran
    env_out = (env_dir / "eplusout.eso").read_text().splitlines()[1:]
    raw_out = (tmp_path / "raw" / "copy0" / "eplusout.eso").read_text().splitlines()[1:]
    assert len(env_out) > steps and env_out == raw_out
    assert raw_seconds(cfg, tmp_path / "const") > 0
    assert env_run(cfg, tmp_path / "envrun")["steps"] == steps


@pytest.mark.slow
def test_a_training_run_replays_in_raw_energyplus(tmp_path, no_leaks):
    """`bench --replay-run`: every step a run took, with its own model and weather, minus pipes and learner."""
    from parallel_eplus.bench import replay_run
    from parallel_eplus.training.config import TrainConfig
    from parallel_eplus.training.train import train

    cfg = TrainConfig(
        workers=2, weathers=["CA", "FL"], run_days=1, timesteps=256, batch_size=128, run_name="r",
        runs_dir=str(tmp_path / "runs"), tensorboard_dir=str(tmp_path / "tb"), keep_episodes=10,
    )  # fmt: skip
    train(cfg, progress=False)
    r = replay_run(tmp_path / "runs" / "r", 2, tmp_path / "replay", progress=False)
    # 128 steps per worker: one whole day (96) and 32 steps of the next, on each worker's weather.
    assert r["episodes"] == 4 and r["steps"] == 256 and r["raw_steps_per_s"] > 0
    cut = TrainConfig(**{**cfg.__dict__, "run_name": "cut", "keep_episodes": 0})
    train(cut, progress=False)
    with pytest.raises(ValueError, match="--keep-episodes"):
        replay_run(tmp_path / "runs" / "cut", 2, tmp_path / "replay2", progress=False)


def test_bench_planner_times_a_committed_planner_and_its_policy_as_the_run_observed(no_leaks):
    """`bench --planner`: the office's committed planner run observed the clock (`--time-features`), so its
    distilled policy takes 14 values where the building has 10 sensors; both act in closed loop for a day."""
    from parallel_eplus.bench.decisions import decisions, format_decisions

    run = Path(__file__).parents[1] / "results/model-based/office-small/runs/office-small-mpc-seed0"
    r = decisions(run, days=1, repeats=1, options="candidates=32")
    assert r["building"] == "office-small" and r["settings"]["candidates"] == 32
    for name in ("planner", "policy"):
        assert r[name]["decisions"] == 144  # a day of 10-minute steps
        assert 0 < r[name]["cpu_ms"]["median"] <= r[name]["cpu_ms"]["p99"]
    assert r["planner"]["cpu_ms"]["median"] > r["policy"]["cpu_ms"]["median"]
    assert "policy network" in format_decisions(r)


@pytest.mark.slow
def test_bench_planner_served_times_each_post_act_as_evaluate_s_client_sends_it_and_the_server_s_cpu(no_leaks):
    """`bench --planner RUN --served`: the planner exported, served in its own process and run in closed loop
    through evaluate's client for a day: every step one POST /act, timed as the integrator sees it, beside the
    server's CPU per decision and the load average."""
    from parallel_eplus.bench.decisions import format_decisions, served
    from parallel_eplus.engine.config import SimulationConfig

    run = Path(__file__).parents[1] / "results/model-based/datacenter-2zone/runs/datacenter-2zone-mpc-seed0"
    s = served(run / "best/planner/planner.pt", SimulationConfig(weather="CA", run_days=1), "candidates=32")
    assert s["requests"] == 96 and 0 < s["round_trip_ms"]["p50"] <= s["round_trip_ms"]["p99"]
    assert s["server_cpu_ms_per_decision"] > 0 and len(s["load_average"]) == 2
    line = format_decisions({"building": "b", "weather": "CA", "settings": {"candidates": 32, "iterations": 3,
                            "shrink": 1.0}, "planner": {"cpu_ms": {"median": 1, "p99": 2}, "wall_ms": {
                            "median": 1, "p99": 2}}, "served": s}).splitlines()[-1]  # fmt: skip
    assert "POST /act" in line and "p99" in line and "load" in line
