"""Short real training runs: 2 EnergyPlus workers, 2-day episodes, small batches."""

from __future__ import annotations

import logging
import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import torch as th
from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

from parallel_eplus.buildings.scoring.reward import RewardConfig
from parallel_eplus.runs.policy_files import _latest_checkpoint, _saved_policy, load_policy
from parallel_eplus.training.callbacks import episodes_per_weather
from parallel_eplus.training.config import TrainConfig
from parallel_eplus.training.train import train

from .conftest import our_pipe_dirs, our_processes


def small_config(tmp_path: Path, name: str, **overrides) -> TrainConfig:
    base = dict(
        workers=2, weathers=["CA", "CO", "FL"], run_days=2, timesteps=1536, batch_size=768,
        run_name=name, runs_dir=str(tmp_path / "runs"), tensorboard_dir=str(tmp_path / "tb"), checkpoint_every=768,
    )  # fmt: skip
    base.update(overrides)
    return TrainConfig(**base)


def scalars(tb_dir: Path) -> dict[str, list]:
    ea = EventAccumulator(str(tb_dir), size_guidance={"scalars": 0})
    ea.Reload()
    return {tag: ea.Scalars(tag) for tag in ea.Tags()["scalars"]}


@pytest.mark.slow
def test_training_writes_metrics_per_weather_gives_three_weathers_equal_episodes_and_resume_keeps_the_cycle(
    tmp_path, no_leaks
):
    """One run (3 one-day episodes per worker, 3 batches): its files, metrics per weather and deterministic policy;
    two workers give three weathers equal episodes; moved, it resumes and keeps the cycle."""
    cfg = small_config(tmp_path, "fair", run_days=1, timesteps=576, batch_size=192, checkpoint_every=192)
    final = train(cfg, progress=False)
    run = tmp_path / "runs" / "fair"
    assert final == run / "model.zip" and (run / "vecnormalize.npz").is_file()
    assert not list(run.rglob("*.pkl"))  # data-only statistics beside the model and in every checkpoint
    assert sorted((run / "checkpoints").glob("model_vecnormalize_*_steps.npz"))
    assert (run / "config.json").is_file() and (run / "episodes.csv").is_file()
    assert sorted((run / "checkpoints").glob("model_*_steps.zip"))
    kept = sorted((run / "episodes").glob("worker-*/episode-*/steps.parquet"))  # the newest 2 per worker (of 3)
    assert len(kept) == 4 and all((ep.parent / "model.idf").is_file() for ep in kept)
    assert not list((run / "episodes").rglob("eplusout.csv"))  # EnergyPlus's own CSV is off in training
    tags = scalars(tmp_path / "tb" / "fair")
    for weather in ("CA", "CO", "FL"):  # worker 0 cycles CA, CO, FL; worker 1 CO, FL, CA
        own = scalars(tmp_path / "tb" / "fair" / f"weather-{weather}")  # one run per weather: one chart per tag
        for metric in ("power_kw", "it_power_kw", "hvac_power_kw", "west_temp_mean", "in_22_25_pct", "return"):
            assert f"episode/{metric}" in own, (weather, metric)
    assert "throughput/env_steps_per_s" in tags and "train/value_loss" in tags
    assert not [t for t in tags if t.startswith("episode/")]  # the weathers' metrics are in their own runs only
    # written as the main logger dumps: the same steps in the main run and each weather's
    steps = {e.step for e in tags["time/fps"]}
    assert {e.step for e in own["episode/power_kw"]} <= steps

    act = load_policy(final)
    obs = np.array([[12.0, 23.0, 24.0, 120e3, 110e3, 10e3]], dtype=np.float32)
    a1, a2 = act(obs), act(obs)
    np.testing.assert_array_equal(a1, a2)
    assert a1.shape == (1, 4) and np.all(np.abs(a1) <= 1)

    csv = run / "episodes.csv"
    assert episodes_per_weather(csv) == {"CA": 2, "CO": 2, "FL": 2}
    assert [e.value for e in tags["episodes/CO"]][-1] == 2
    # Moved (as to another machine, or restored from a commit): the run continues where it is now, logs too.
    home = tmp_path / "moved"
    home.mkdir()
    for folder in ("runs", "tb"):
        (tmp_path / folder).rename(home / folder)
    csv = home / "runs" / "fair" / "episodes.csv"
    last = csv.read_text().splitlines()[-1].split(",", 1)[1]
    with csv.open("a") as f:  # an episode after the last save, as a run killed then leaves it: collected again
        f.write(f"999999,{last}\n")
    train(small_config(tmp_path, "fair", run_days=1, timesteps=1152, batch_size=192), resume=home / "runs" / "fair")
    assert not (tmp_path / "runs").exists() and not (tmp_path / "tb").exists()
    assert episodes_per_weather(csv) == {"CA": 4, "CO": 4, "FL": 4}
    assert [e.value for e in scalars(home / "tb" / "fair")["episodes/CO"]][-1] == 4
    order = pd.read_csv(csv).groupby("worker")["weather"].apply(list).to_dict()
    assert order == {0: ["CA", "CO", "FL"] * 2, 1: ["CO", "FL", "CA"] * 2}


@pytest.mark.slow
def test_ray_backend_trains_locally(tmp_path, no_leaks, caplog):
    pytest.importorskip("ray")
    cfg = small_config(tmp_path, "ray", weathers=["CA"], run_days=1, timesteps=384, batch_size=384, backend="ray",
                       workers_per_actor=1)  # fmt: skip
    with caplog.at_level(logging.INFO, logger="parallel_eplus"):
        final = train(cfg, progress=False)
    assert final.is_file()
    assert "Ray cluster: 1 node(s)" in caplog.text  # the resources, then the workers each node got
    assert re.search(r"\): 2 worker\(s\)", caplog.text), caplog.text
    assert "episode/power_kw" in scalars(tmp_path / "tb" / "ray" / "weather-CA")


@pytest.mark.slow
def test_interrupt_saves_checkpoint_leaves_nothing_and_resume_continues(tmp_path):
    pipes_before = our_pipe_dirs()
    cmd = [
        sys.executable, "-m", "parallel_eplus.cli", "train", "--workers", "2", "--weathers", "CA",
        "--run-days", "1", "--timesteps", "100000", "--batch-size", "192", "--run-name", "cut", "--quiet",
    ]  # fmt: skip
    env = {**os.environ, "PYTHONUNBUFFERED": "1"}
    proc = subprocess.Popen(cmd, cwd=tmp_path, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    episodes = tmp_path / "runs" / "cut" / "episodes.csv"
    deadline = time.monotonic() + 600  # (a machine loaded by other runs can take minutes)
    while not episodes.exists() and time.monotonic() < deadline and proc.poll() is None:
        time.sleep(0.5)
    assert episodes.exists(), proc.communicate()[0] if proc.poll() is not None else "no episode within 600 s"
    with pytest.raises(ValueError, match="still being trained"):  # a second trainer in its folder: refused
        train(TrainConfig(timesteps=512), resume=tmp_path / "runs" / "cut", progress=False)
    proc.send_signal(signal.SIGINT)
    out, _ = proc.communicate(timeout=60)
    assert proc.returncode == 130, out
    assert "checkpoint saved" in out
    assert our_processes() == []
    assert our_pipe_dirs() - pipes_before == set()
    checkpoints = sorted((tmp_path / "runs" / "cut" / "checkpoints").glob("model_*_steps.zip"))
    assert checkpoints
    cut_at = int(checkpoints[-1].stem.split("_")[1])
    assert cut_at > 0

    resumed = train(TrainConfig(timesteps=cut_at + 192), resume=tmp_path / "runs" / "cut", progress=False)
    from sb3_contrib import TRPO

    model = TRPO.load(resumed, device="cpu")
    assert model.num_timesteps >= cut_at + 192
    steps = [e.step for e in scalars(tmp_path / "tensorboard_logs" / "cut")["time/fps"]]
    assert max(steps) > cut_at  # TensorBoard curves continue past the cut, not from zero
    # A finished run resumes from its final model, which is newer than its last checkpoint.
    assert _latest_checkpoint(tmp_path / "runs" / "cut") == resumed


@pytest.mark.slow
def test_init_from_starts_a_new_run_from_a_policy(tmp_path, no_leaks):
    from parallel_eplus.runs.norm_stats import read_stats

    base = train(small_config(tmp_path, "base", weathers=["CA"], timesteps=768, time_features=True), progress=False)
    with pytest.raises(ValueError, match="--time-features"):  # fewer observations: refused before EnergyPlus starts
        train(small_config(tmp_path, "wrong", init_from=str(base)), progress=False)
    # More observations: they enter with zero weights, so the new run starts as the saved policy acts.
    grown = small_config(tmp_path, "grown", timesteps=0, init_from=str(base), time_features=True)
    grown.schedule_features = True
    old, new = (_saved_policy(m).state_dict() for m in (base, train(grown, progress=False)))
    for key in old:
        if key.endswith("_net.0.weight"):  # the input layers: 6 sensors + 4 time features, then 5 new columns
            assert th.equal(new[key][:, :10], old[key]) and not new[key][:, 10:].any(), key
        else:
            assert th.equal(new[key], old[key]), key
    reward = RewardConfig(center_c=23.0, lower_c=22.5, upper_c=23.5)
    tuned = small_config(
        tmp_path, "tuned", weathers=["CO"], timesteps=512, batch_size=512, reward=reward, time_features=True
    )
    tuned.init_from = str(base)
    final = train(tuned, progress=False)
    counts = []
    for model in (base, final):
        counts.append(read_stats(model.parent / "vecnormalize.npz").obs_count)
    assert counts[1] > counts[0] + 500  # inherited the statistics, then kept updating them
    saved = TrainConfig.from_json((final.parent / "config.json").read_text())
    assert saved.init_from == str(base) and saved.reward == reward and saved.batch_size == 512


@pytest.mark.slow
def test_ppo_trains_the_same_way_and_its_policy_acts(tmp_path, no_leaks):
    from parallel_eplus.evaluation.controllers import policy_controller

    final = train(small_config(tmp_path, "ppo", weathers=["CA"], timesteps=768, algorithm="ppo"), progress=False)
    assert TrainConfig.from_json((final.parent / "config.json").read_text()).algorithm == "ppo"
    act = load_policy(final)
    obs = np.array([[12.0, 23.0, 24.0, 120e3, 110e3, 10e3]], dtype=np.float32)
    a = act(obs)
    assert a.shape == (1, 4) and np.all(np.abs(a) <= 1)
    assert policy_controller(str(final)).label == "PPO (CA)"
    with pytest.raises(ValueError, match="unknown algorithm"):
        train(small_config(tmp_path, "bad", algorithm="a2c"), progress=False)


def test_residual_settings_are_checked_before_anything_runs(tmp_path):
    with pytest.raises(ValueError, match="needs --residual SCALE"):
        train(small_config(tmp_path, "no-scale", residual_space="demand"), progress=False)
    with pytest.raises(ValueError, match="unknown --residual-space"):
        train(small_config(tmp_path, "bad-space", residual_scale=1.0, residual_space="flows"), progress=False)
    assert not (tmp_path / "runs").exists()  # refused before a run directory or an EnergyPlus process


@pytest.mark.slow
def test_sac_trains_checkpoints_resumes_and_its_policy_evaluates(tmp_path, no_leaks, caplog):
    from parallel_eplus.evaluation.controllers import policy_controller
    from parallel_eplus.evaluation.sweep import run_sweep
    from parallel_eplus.training.config import SACSettings

    sac = SACSettings(learning_starts=100, batch_size=64, buffer_size=5000)
    cfg = small_config(tmp_path, "sac", weathers=["CA", "CO"], run_days=1, timesteps=400, algorithm="sac",
                       checkpoint_every=200, sac=sac)  # fmt: skip
    final = train(cfg, progress=False)
    run = final.parent
    assert (run / "model_replay_buffer.pkl").is_file()  # beside the final model
    checkpoint = run / "checkpoints" / "model_200_steps.zip"
    assert checkpoint.is_file() and not (run / "checkpoints" / "model_200_steps_replay_buffer.pkl").exists()
    tags = scalars(tmp_path / "tb" / "sac")
    for weather in ("CA", "CO"):  # 1-day episodes: 96 steps, two per worker and weather in 400 steps
        assert "episode/in_22_25_pct" in scalars(tmp_path / "tb" / "sac" / f"weather-{weather}")
    assert "train/actor_loss" in tags and "throughput/env_steps_per_s" in tags

    # From the final model: its replay buffer comes back; from a periodic checkpoint: an empty buffer, said so.
    resumed = TrainConfig(timesteps=600)
    final = train(resumed, resume=run, progress=False)
    assert pd.read_csv(run / "episodes.csv")["timesteps"].max() > 400
    with caplog.at_level("WARNING"):
        train(TrainConfig(timesteps=400), resume=checkpoint, progress=False)  # 200 steps on from the checkpoint
    assert "empty buffer" in caplog.text

    act = load_policy(final)
    obs = np.array([[12.0, 23.0, 24.0, 120e3, 110e3, 10e3]], dtype=np.float32)
    a1, a2 = act(obs), act(obs)
    np.testing.assert_array_equal(a1, a2)
    assert a1.shape == (1, 4) and np.all(np.abs(a1) <= 1)
    controller = policy_controller(str(final))
    assert controller.label == "SAC (CA-CO)"
    df = run_sweep([controller], ["CA"], run_days=1, workers=1, out_dir=tmp_path / "eval", progress=False)
    assert len(df) == 1 and 0 <= df["in_band_pct"].iloc[0] <= 100
