"""`parallel-eplus runs`: every run's state read from what it writes, including runs killed outright and old ones."""

from __future__ import annotations

import json
import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest

from parallel_eplus.engine.pipes import leftovers
from parallel_eplus.runs import registry
from parallel_eplus.runs.run_files import STATUS_FILE
from parallel_eplus.runs.run_status import TRIAL_VARIABLE, now_iso
from parallel_eplus.training.train import train

from .conftest import our_processes
from .test_train import small_config

ENV = {**os.environ, "PYTHONUNBUFFERED": "1"}


def _cli(*args: str) -> list[str]:
    return [sys.executable, "-m", "parallel_eplus.cli", *args]


def _runs(cwd: Path, *args: str) -> str:
    return subprocess.run(_cli("runs", *args), cwd=cwd, capture_output=True, text=True, check=True).stdout


def _run_folder(root: Path, name: str, status: dict | None, model: bool = False) -> Path:
    run = root / name
    (run / "checkpoints").mkdir(parents=True)
    (run / "config.json").write_text(json.dumps({"timesteps": 1000, "weathers": ["CA"]}))
    (run / "episodes.csv").write_text("timesteps,weather,in_band_pct,power_kw\n96,CA,50.0,120.0\n192,CA,60.0,110.0\n")
    if status is not None:
        (run / STATUS_FILE).write_text(json.dumps(status))
    if model:
        (run / "model.zip").write_bytes(b"")
    return run


def _status(**changes) -> dict:
    me = os.getpid()
    base = {"state": "running", "pid": me, "pid_started": leftovers.start_time(me), "host": socket.gethostname(),
            "trial": None, "updated": now_iso(), "steps": 192, "planned": 1000, "wall_s": 5.0}  # fmt: skip
    return base | changes


def test_states_from_status_files_and_from_an_older_versions_files(tmp_path):
    dead = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True, text=True)
    _run_folder(tmp_path, "alive", _status())
    _run_folder(tmp_path, "killed", _status(pid=int(dead.stdout)))  # said running; its process is gone
    _run_folder(tmp_path, "recycled", _status(pid_started="1"))  # its pid now belongs to another process
    _run_folder(tmp_path, "elsewhere", _status(host="node-2", trial="t-3"))  # not checkable from here, recent
    _run_folder(tmp_path, "silent", _status(host="node-2", updated="2020-01-01T00:00:00+00:00"))
    _run_folder(tmp_path, "done", _status(state="finished", steps=1152), model=True)
    _run_folder(tmp_path, "old-finished", None, model=True)
    _run_folder(tmp_path, "old-stopped", None)
    _run_folder(tmp_path / "sweep", "trial-0", _status(state="failed", error="EnergyPlusError: hung"))
    (tmp_path / "not-a-run").mkdir()
    runs = {r.name: r for r in registry.list_runs(tmp_path)}
    states = {name: r.state for name, r in runs.items()}
    assert states == {
        "alive": "running", "killed": "failed", "recycled": "failed", "elsewhere": "running", "silent": "failed",
        "done": "finished", "old-finished": "finished", "old-stopped": "stopped", "sweep/trial-0": "failed",
    }  # fmt: skip
    assert runs["killed"].process.endswith(" gone") and "killed" in runs["killed"].note
    assert runs["elsewhere"].process == "trial t-3 (" + f"{os.getpid()}@node-2)"
    assert runs["sweep/trial-0"].note == "EnergyPlusError: hung"
    old = runs["old-stopped"]
    assert (old.episodes, old.steps, old.planned, old.latest["CA"]["in_band_pct"]) == (2, 192, 1000, 60.0)
    assert "earlier version" in old.note
    assert runs["done"].steps == 1152 and runs["done"].checkpoint.name == "model.zip"
    assert registry.resolve_run("sweep/trial-0", tmp_path) == tmp_path / "sweep" / "trial-0"
    with pytest.raises(FileNotFoundError, match="no run 'nope'.*alive"):
        registry.resolve_run("nope", tmp_path)
    with pytest.raises(ValueError, match="not running"):
        registry.stop_run(runs["done"])


def test_a_model_based_run_shows_its_checkpoint(tmp_path):
    """A model-based (mpc) run saves checkpoints/mpc_<steps>_steps.pt: `runs` shows the newest as its checkpoint
    and counts its steps, as it does a model-free run's model_<steps>_steps.zip."""
    run = _run_folder(tmp_path / "runs", "mpc", _status(state="stopped", steps=0))
    for steps in (2500, 5000):
        (run / "checkpoints" / f"mpc_{steps}_steps.pt").write_bytes(b"")
    info = registry.read_run(run, tmp_path / "runs")
    assert info.checkpoint == run / "checkpoints" / "mpc_5000_steps.pt" and info.steps == 5000
    out = _runs(tmp_path)
    line = next(row for row in out.splitlines() if row.startswith("mpc "))
    assert "mpc_5000_steps.pt" in line, out


@pytest.mark.slow
def test_a_finished_run_and_the_same_run_as_an_older_version_left_it(tmp_path, no_leaks, monkeypatch):
    monkeypatch.setenv(TRIAL_VARIABLE, "trial-7")  # as a Ray Tune sweep sets it
    # one batch of 2 one-day episodes a worker: the workers' weather cycles (CA, CO and CO, FL) cover all three
    cfg = small_config(tmp_path, "short", run_days=1, timesteps=384, batch_size=384, checkpoint_every=384)
    train(cfg, progress=False)
    status = json.loads((tmp_path / "runs" / "short" / STATUS_FILE).read_text())
    assert status["state"] == "finished" and status["trial"] == "trial-7" and status["steps"] == status["planned"]
    assert status["pid"] == os.getpid() and status["wall_s"] > 0
    out = _runs(tmp_path)
    assert out.splitlines()[1].split()[:3] == ["short", "finished", "trial"], out
    assert "384/384" in out and "model.zip" in out and all(f"{w} " in out for w in ("CA", "CO", "FL"))
    (tmp_path / "runs" / "short" / STATUS_FILE).unlink()  # as a run from before status.json left it
    [info] = registry.list_runs(tmp_path / "runs")
    assert (info.state, info.steps, info.planned, info.wall_s) == ("finished", 384, 384, None)
    shown = _runs(tmp_path, "show", "short")
    assert "state       finished" in shown and "latest episode of each weather" in shown and "algorithm" in shown


def _start(cwd: Path, name: str) -> subprocess.Popen:
    cmd = _cli("train", "--workers", "2", "--weathers", "CA,FL", "--run-days", "1", "--timesteps", "100000",
               "--batch-size", "192", "--checkpoint-every", "192", "--run-name", name, "--quiet")  # fmt: skip
    return subprocess.Popen(cmd, cwd=cwd, env=ENV, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)


def _wait_running(cwd: Path, name: str, proc: subprocess.Popen) -> registry.RunInfo:
    """Until the run says it is running, past its first checkpoint (one batch, 192 steps)."""
    deadline = time.monotonic() + 180
    while True:
        assert proc.poll() is None, proc.communicate()[0]
        assert time.monotonic() < deadline, "the run did not get going within 180 s"
        if (cwd / "runs" / name / STATUS_FILE).is_file():
            info = registry.read_run(cwd / "runs" / name)
            if info.state == "running" and info.checkpoint is not None and info.steps >= 192:
                return info
        time.sleep(0.5)


@pytest.mark.slow
def test_runs_stop_ends_a_running_training_with_a_checkpoint_and_nothing_left(tmp_path, no_leaks):
    proc = _start(tmp_path, "live")
    try:
        running = _wait_running(tmp_path, "live", proc)
        assert running.process == f"{proc.pid}@{socket.gethostname()}"
        assert f"live  running  {proc.pid}@" in _runs(tmp_path)
        stop = subprocess.run(_cli("runs", "stop", "live"), cwd=tmp_path, capture_output=True, text=True)
        assert stop.returncode == 0, stop.stdout + stop.stderr
        assert proc.wait(timeout=60) == 130  # it ended as Ctrl-C ends it
    finally:
        if proc.poll() is None:
            proc.kill()
    assert "live: stopped at step" in stop.stdout and "no EnergyPlus process or pipe left" in stop.stdout
    info = registry.read_run(tmp_path / "runs" / "live")
    assert info.state == "stopped" and info.checkpoint.name == f"model_{info.steps}_steps.zip"
    assert our_processes() == [] and not [d for d in leftovers.pipe_dirs() if f"-{proc.pid}-" in d.name]


@pytest.mark.slow
def test_a_trainer_killed_with_sigkill_is_listed_as_failed_not_running(tmp_path, no_leaks):
    proc = _start(tmp_path, "killed")
    try:
        _wait_running(tmp_path, "killed", proc)
        proc.send_signal(signal.SIGKILL)
        proc.wait(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
    try:
        assert json.loads((tmp_path / "runs" / "killed" / STATUS_FILE).read_text())["state"] == "running"
        line = _runs(tmp_path).splitlines()[1]
        assert line.split()[:3] == ["killed", "failed", f"{proc.pid}@{socket.gethostname()}"] and " gone " in line
        shown = _runs(tmp_path, "show", "killed")
        assert "killed (SIGKILL, out of memory?)" in shown
        stop = subprocess.run(_cli("runs", "stop", "killed"), cwd=tmp_path, capture_output=True, text=True)
        assert stop.returncode == 2 and "not running (failed)" in stop.stderr
    finally:  # no cleanup ran in the killed trainer: its EnergyPlus processes exit as their pipes close
        deadline = time.monotonic() + 30
        while our_processes() and time.monotonic() < deadline:
            time.sleep(0.2)
        leftovers.sweep()


def test_a_scratch_folder_whose_owner_is_gone_is_swept_and_a_live_ones_kept(tmp_path):
    """A Ray evaluation task's folder (evaluation/ray_sweep.py) names its owner; Ray's shutdown kills its worker
    outright, so `clean` and the next run's first pipe remove it once that process is gone."""
    dead = subprocess.Popen([sys.executable, "-c", "pass"])
    dead.wait()
    gone, alive = tmp_path / "parallel-eplus-eval-gone", tmp_path / "parallel-eplus-eval-alive"
    for folder in (gone, alive):
        (folder / "episodes").mkdir(parents=True)
    leftovers.write_owner(alive)
    (gone / leftovers.OWNER_FILE).write_text(f"{dead.pid} 1\n")  # a process that ended
    assert leftovers.sweep(tmp_path) == [gone]
    assert alive.is_dir() and not gone.exists()
