"""Sweeps and seeds as Ray Tune trials: real trainings (one-day episodes, tiny batches) queued on this machine."""

from __future__ import annotations

import itertools
import json
import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import pandas as pd
import pytest

from parallel_eplus.cli import main
from parallel_eplus.experiments.sweep_spec import load_spec, trial_config, trial_name

from .conftest import our_pipe_dirs, our_processes

BASE = """
[train]
workers = 2
weathers = "CA"
run_days = 1
timesteps = 384
batch_size = 192
checkpoint_every = 192
"""


def write_spec(tmp_path: Path, text: str, name: str = "spec.toml") -> Path:
    path = tmp_path / name
    path.write_text(text)
    return path


def interrupt_at_first_save(cmd: list[str], cwd: Path, saves: list[tuple[Path, str]], wait_s: float) -> str:
    """Run a sweep until each (folder, pattern) of `saves` holds a matching file, then Ctrl-C it; returns its output."""
    proc = subprocess.Popen(cmd, cwd=cwd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                            env={**os.environ, "PYTHONUNBUFFERED": "1"})  # fmt: skip
    deadline = time.monotonic() + wait_s
    while not all(any(d.glob(p)) for d, p in saves) and time.monotonic() < deadline and proc.poll() is None:
        time.sleep(0.5)
    assert proc.poll() is None, proc.communicate()[0]
    proc.send_signal(signal.SIGINT)
    out, _ = proc.communicate(timeout=120)
    assert proc.returncode == 130, out
    return out


@pytest.mark.parametrize(
    "text, message",
    [
        ('name = "s"\n[train]\nbatch_sise = 4', "unknown setting 'batch_sise'"),
        ('name = "s"\n[grid]\nlearning_rate = [1e-3]', "trpo.learning_rate"),  # says which one it could be
        ('name = "s"\n[train]\nbackend = "ray"', "is the sweep's to set"),
        ('name = "s"\n[grid]\nseed = [0, 1]', "seeds = [...]"),
        ('name = "s"\n[grid]\nalgorithm = "ppo"', "takes a list"),
        ('name = "s"\nseeds = [0, 0]', "distinct whole numbers"),
        ('name = "a b"', "folder name"),
        ('name = "s"\n[search]\nsamples = 2\n[search.space]\n"trpo.target_kl" = { normal = [0, 1] }', "loguniform"),
        ('name = "s"\nseeds = [0, 1]\n[search]\n[search.space]\nbatch_size = { choice = [96, 192] }', "one seed"),
        ('name = "s"\n[sweep]\nx = 1', "unknown section"),
    ],
)
def test_a_bad_spec_is_refused_before_anything_runs(tmp_path, text, message):
    with pytest.raises(ValueError, match=message.replace("[", r"\[").replace("(", r"\(")):
        load_spec(write_spec(tmp_path, text))


def test_spec_keys_are_a_runs_config_keys_and_name_its_trials(tmp_path):
    reward = tmp_path / "reward.json"
    reward.write_text('{"power_weight": 2e-5}')
    spec = load_spec(
        write_spec(
            tmp_path,
            f"""name = "grid"
seeds = [0, 1]
[train]
weathers = "CA,FL"
batch-size = 192
reward = "{reward}"
[train.trpo]
target_kl = 0.02
[train.comfort]
target_pct = 99.0
[grid]
algorithm = ["trpo", "ppo"]
"ppo.learning_rate" = [3e-4, 1e-3]
""",
        )
    )
    assert spec.base["weathers"] == ["CA", "FL"] and spec.base["batch_size"] == 192
    assert spec.base["reward.power_weight"] == 2e-5 and spec.base["trpo.target_kl"] == 0.02
    assert spec.base["comfort.target_pct"] == 99.0
    assert spec.varied == ["algorithm", "ppo.learning_rate", "seed"]
    settings = {**spec.base, "algorithm": "ppo", "ppo.learning_rate": 1e-3, "seed": 1}
    cfg = trial_config(settings, str(tmp_path / "runs" / "grid"), str(tmp_path / "tb" / "grid"), "t")
    assert (cfg.algorithm, cfg.ppo.learning_rate, cfg.seed, cfg.reward.power_weight) == ("ppo", 1e-3, 1, 2e-5)
    assert cfg.trpo.target_kl == 0.02 and cfg.comfort.target_pct == 99.0
    assert cfg.run_dir == tmp_path / "runs" / "grid" / "t" and cfg.backend == "local"
    assert trial_name(settings, spec.varied) == "algorithm-ppo_learning_rate-0.001_seed-1"
    assert trial_name({"seed": 2}, ["seed"]) == "seed-2"


@pytest.mark.parametrize(
    "extra, message",
    [(["--seeds", "0,x"], "--seeds takes whole numbers"), (["--seeds", "1,1"], "distinct whole numbers"),
     (["--seeds", "0,1", "--backend", "ray"], "drop --backend ray")],
)  # fmt: skip
def test_train_seeds_refuses_bad_input_before_ray_starts(tmp_path, monkeypatch, caplog, extra, message):
    monkeypatch.chdir(tmp_path)
    assert main(["train", "--workers", "1", "--run-name", "s", *extra]) == 2
    assert message in caplog.text and not (tmp_path / "runs").exists()


def run_span(run: Path) -> tuple[float, float]:
    """When a run started (its config.json) and finished (its model.zip)."""
    return (run / "config.json").stat().st_mtime, (run / "model.zip").stat().st_mtime


@pytest.mark.slow
def test_two_seeds_queue_two_workers_each_and_both_finish_as_run_folders(tmp_path, monkeypatch, capsys, no_leaks):
    monkeypatch.chdir(tmp_path)  # 2 trials of 2 workers on 2 cores: the second queues behind the first
    argv = ["train", "--workers", "2", "--weathers", "CA,FL", "--run-days", "1", "--timesteps", "192",
            "--batch-size", "192", "--run-name", "seeds", "--seeds", "0,1"]  # fmt: skip
    assert main(argv) == 0
    out = capsys.readouterr().out
    runs = [tmp_path / "runs" / "seeds" / f"seed-{s}" for s in range(2)]
    for seed, run in enumerate(runs):
        assert json.loads((run / "config.json").read_text())["seed"] == seed
        assert (run / "model.zip").is_file() and (run / "vecnormalize.npz").is_file()
        assert len(pd.read_csv(run / "episodes.csv")) == 2  # 2 workers x 1 one-day episode
        assert (tmp_path / "tensorboard_logs" / "seeds" / f"seed-{seed}").is_dir()
        assert f"seed-{seed}" in out and "finished" in out
    spans = sorted(run_span(r) for r in runs)  # 2 cores, 2 workers a trial: one trial at a time
    assert all(later[0] >= earlier[1] for earlier, later in itertools.pairwise(spans)), spans
    # an ordinary run: `evaluate` reads a trial's folder
    assert main(["evaluate", "--policy", str(runs[0]), "--weathers", "CA", "--run-days", "1", "--workers", "1",
                 "--out", str(tmp_path / "eval"), "--quiet"]) == 0  # fmt: skip


@pytest.mark.slow
def test_a_failing_trial_is_reported_and_the_others_finish(tmp_path, monkeypatch, capsys, broken_weather, no_leaks):
    monkeypatch.chdir(tmp_path)
    spec = write_spec(
        tmp_path,
        f"""name = "mixed"
{BASE.replace("workers = 2", "workers = 1").replace("384", "192")}
[grid]
weathers = [["CA"], ["{broken_weather}"]]
algorithm = ["trpo", "nonsense"]
""",
    )
    assert main(["sweep", str(spec)]) == 1  # some trials failed
    out = capsys.readouterr().out
    root = tmp_path / "runs" / "mixed"
    assert (root / "weathers-CA_algorithm-trpo" / "model.zip").is_file()
    lines = {ln.split()[0]: ln for ln in out.splitlines() if ln.startswith("weathers-")}
    assert "finished" in lines["weathers-CA_algorithm-trpo"]
    assert "failed" in lines["weathers-CA_algorithm-nonsense"]
    broken = next(name for name in lines if "Broken" in name and "trpo" in name)
    assert "failed" in lines[broken]
    assert "unknown algorithm 'nonsense'" in out  # each failure's cause, in the closing report
    assert f"{broken} failed: EnergyPlusError" in out


@pytest.mark.slow
def test_ctrl_c_stops_every_trial_with_a_checkpoint_and_the_same_command_resumes(tmp_path):
    """Two trials at once (one worker each), a third queued: Ctrl-C once both saved; run again, each continues from
    its own save: the model-free trial from SB3's zip, the model-based (`mpc`) one from checkpoints/mpc_<steps>_
    steps.pt (it started afresh before), and the queued one starts."""
    pipes_before = our_pipe_dirs()
    spec = write_spec(tmp_path, 'name = "cut"\n' + BASE.replace("384", "20000").replace("workers = 2", "workers = 1")
                      + '[train.mpc]\nexplore_steps = 96\nrefit_every = 96\nepochs = 5\ncandidates = 32\n'
                      '[grid]\nalgorithm = ["trpo", "mpc", "ppo"]\n')  # fmt: skip
    cmd = [sys.executable, "-m", "parallel_eplus.cli", "sweep", str(spec)]
    root = tmp_path / "runs" / "cut"
    checkpoints, mpc = root / "algorithm-trpo" / "checkpoints", root / "algorithm-mpc" / "checkpoints"
    out = interrupt_at_first_save(cmd, tmp_path, [(checkpoints, "model_*_steps.zip"), (mpc, "mpc_*_steps.npz")], 240)
    assert our_processes() == [] and our_pipe_dirs() - pipes_before == set()
    cut_at = max(int(p.stem.split("_")[1]) for p in checkpoints.glob("model_*_steps.zip"))
    mpc_at = max(int(p.stem.split("_")[1]) for p in mpc.glob("mpc_*_steps.pt"))
    # saved on the stop, at the step the trial stopped: its status.json and the sweep's closing table say so (the
    # trial's own log line reaches this output only if Ray's log monitor forwards it before the trial's process ends)
    status = json.loads((checkpoints.parent / "status.json").read_text())
    assert status["state"] == "stopped" and status["steps"] == cut_at, (status, out)
    assert re.search(rf"algorithm-trpo\s+stopped\s+{cut_at}\b", out), out
    assert "algorithm-ppo" in out and not (root / "algorithm-ppo" / "config.json").exists()  # queued

    spec.write_text(spec.read_text().replace("20000", str(max(cut_at, mpc_at) + 192)))  # only timesteps may change
    resumed = subprocess.run(cmd, cwd=tmp_path, capture_output=True, text=True, timeout=600)
    assert resumed.returncode == 0, resumed.stdout + resumed.stderr
    err = resumed.stderr
    assert f"resuming algorithm-trpo from {checkpoints / f'model_{cut_at}_steps.zip'} at step {cut_at}" in err, err
    assert re.search(rf"resuming algorithm-mpc from \S+mpc_{mpc_at}_steps.pt at step {mpc_at}", err), err
    steps = pd.read_csv(root / "algorithm-trpo" / "episodes.csv")["timesteps"]
    assert steps.is_monotonic_increasing and steps.max() > cut_at
    assert json.loads((mpc.parent / "status.json").read_text())["state"] == "finished"
    assert all((root / f"algorithm-{a}" / "model.zip").is_file() for a in ("trpo", "mpc", "ppo"))
    assert our_processes() == [] and our_pipe_dirs() - pipes_before == set()


@pytest.mark.slow
def test_an_optuna_search_draws_its_trials_and_names_the_best(tmp_path, monkeypatch, capsys, no_leaks):
    pytest.importorskip("optuna")
    monkeypatch.chdir(tmp_path)
    spec = write_spec(
        tmp_path,
        f"""name = "search"
{BASE.replace("workers = 2", "workers = 1").replace("batch_size = 192", "").replace("384", "192")}
[search]
samples = 2
metric = "power_kw"
[search.space]
batch_size = {{ choice = [96, 192] }}
"trpo.target_kl" = {{ loguniform = [0.003, 0.03] }}
""",
    )
    assert main(["sweep", str(spec)]) == 0
    out = capsys.readouterr().out
    trials = [p for p in (tmp_path / "runs" / "search").iterdir() if "_batch_size-" in p.name]
    assert len(trials) == 2 and all((p / "model.zip").is_file() for p in trials)
    for p in trials:  # each trial trained with what the search drew
        saved = json.loads((p / "config.json").read_text())
        assert p.name.split("_batch_size-")[1].startswith(f"{saved['batch_size']}_target_kl-")
        assert 0.003 <= saved["trpo"]["target_kl"] <= 0.03
    assert "best by power_kw (min): " in out


@pytest.mark.slow
def test_a_signal_to_one_trial_stops_it_with_a_checkpoint_and_the_others_go_on(tmp_path):
    """What `parallel-eplus runs stop` does to a trial: a signal to the process that runs it. SIGINT (`runs stop`'s:
    Ray workers block it) to the first trial once it saved a checkpoint, SIGTERM (kill's) to the second, which the
    sweep started after the first stopped. One sweep for both signals: its trials queue for the 2 cores."""
    pipes_before = our_pipe_dirs()
    spec = write_spec(tmp_path, 'name = "one"\n' + BASE + "[grid]\ntimesteps = [20000, 20001]\n")
    cmd = [sys.executable, "-m", "parallel_eplus.cli", "sweep", str(spec)]
    proc = subprocess.Popen(cmd, cwd=tmp_path, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                            env={**os.environ, "PYTHONUNBUFFERED": "1"})  # fmt: skip
    long = ["timesteps-20000", "timesteps-20001"]
    signals: dict[str, int] = {}
    deadline = time.monotonic() + 360
    while len(signals) < 2 and time.monotonic() < deadline and proc.poll() is None:
        saved = [t for t in long if t not in signals and any(_checkpoints(tmp_path, t).glob("model_*_steps.zip"))]
        if not saved:
            time.sleep(0.5)
            continue
        owners = {d.split("-")[2] for d in our_pipe_dirs() - pipes_before}  # parallel-eplus-<pid>-...: the trial's
        assert len(owners) == 1, owners  # one trial at a time on the 2 cores
        owner, signum = owners.pop(), signal.SIGINT if not signals else signal.SIGTERM
        os.kill(int(owner), signum)
        signals[saved[0]] = signum
        while any(d.split("-")[2] == owner for d in our_pipe_dirs()) and time.monotonic() < deadline:
            time.sleep(0.5)  # until that trial's workers are gone
    assert len(signals) == 2 and set(signals.values()) == {signal.SIGINT, signal.SIGTERM}, (signals, proc.poll())
    out, _ = proc.communicate(timeout=300)
    assert proc.returncode == 130, out  # a trial stopped: the sweep says how to continue it
    states = {ln.split()[0]: ln.split()[1] for ln in out.splitlines() if ln.startswith("timesteps-")}
    assert states == {"timesteps-20000": "stopped", "timesteps-20001": "stopped"}, out
    for trial in long:
        checkpoints = _checkpoints(tmp_path, trial)
        cut_at = max(int(p.stem.split("_")[1]) for p in checkpoints.glob("model_*_steps.zip"))
        status = json.loads((checkpoints.parent / "status.json").read_text())  # saved on the stop (as above)
        assert status["state"] == "stopped" and status["steps"] == cut_at, (trial, status, out)
    assert our_processes() == [] and our_pipe_dirs() - pipes_before == set()


def _checkpoints(tmp_path: Path, trial: str) -> Path:
    return tmp_path / "runs" / "one" / trial / "checkpoints"
