"""Faults during a training run: its EnergyPlus workers or the trainer itself killed, stopped, cut off.

The trainer runs as a real `parallel-eplus train` process (or `train()` in this process where EnergyPlus is
the target); every case checks the outcome and that nothing is left behind. SIGINT of the trainer is
tests/test_train.py's `test_interrupt_saves_checkpoint_leaves_nothing_and_resume_continues`.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pandas as pd
import pytest

from parallel_eplus.engine.pipes import leftovers
from parallel_eplus.errors import EnergyPlusError
from parallel_eplus.training.train import train

from ..conftest import our_processes
from ..test_train import small_config
from .strikes import process_state, strike_after_step, wait_for_state


def _private_env(tmp_path: Path) -> dict[str, str]:
    """The trainer's and `clean`'s environment, with a temp folder of the test's own: any process on this shared
    machine sweeps dead owners' pipe directories under /tmp as it makes its first pipe (leftovers.py), which
    would race with what the test checks it left behind."""
    private = tmp_path / "tmp"
    private.mkdir(exist_ok=True)
    return {**os.environ, "PYTHONUNBUFFERED": "1", "TMPDIR": str(private)}


def _cli(*args: str) -> list[str]:
    return [sys.executable, "-m", "parallel_eplus.cli", *args]


def _train_cmd(name: str, timesteps: int = 100_000) -> list[str]:
    return _cli(
        "train", "--workers", "2", "--weathers", "CA,FL", "--run-days", "1", "--timesteps", str(timesteps),
        "--batch-size", "192", "--checkpoint-every", "192", "--run-name", name, "--quiet",
    )  # fmt: skip


def _checkpoints(run: Path) -> list[Path]:
    return sorted((run / "checkpoints").glob("model_*_steps.zip"), key=lambda p: int(p.stem.split("_")[1]))


def _wait_for(predicate, timeout: float, what: str, proc: subprocess.Popen | None = None) -> float:
    t0 = time.monotonic()
    while not predicate():
        if proc is not None and proc.poll() is not None:
            raise AssertionError(f"{what}: the trainer exited first:\n{proc.communicate()[0]}")
        assert time.monotonic() - t0 < timeout, f"{what} not within {timeout} s"
        time.sleep(0.2)
    return time.monotonic() - t0


def _pipe_dirs_of(pid: int, env: dict[str, str]) -> set[str]:
    return {d for d in os.listdir(env["TMPDIR"]) if d.startswith(f"{leftovers.PREFIX}{pid}-")}


def _energyplus_children(pid: int) -> list[int]:
    out = subprocess.run(["pgrep", "-P", str(pid), "-f", leftovers.CALLBACK_MODULE], capture_output=True, text=True)
    return [int(p) for p in out.stdout.split()]


def _stop(proc: subprocess.Popen, sig: int) -> str:
    """Signal the trainer; its output (whichever stream was piped) once it has exited and every EnergyPlus process
    is gone."""
    proc.send_signal(sig)
    out = "".join(text or "" for text in proc.communicate(timeout=60))
    gone = _wait_for(lambda: our_processes() == [], 60, "every EnergyPlus process gone")
    print(f"{sig.name}: EnergyPlus processes gone {gone:.1f} s after the trainer exited")
    return out


def _resumed_from(err: str, last: Path) -> int:
    steps = int(last.stem.split("_")[1])
    assert f"resuming cut from runs/cut/checkpoints/{last.name} at step {steps}" in err, err
    return steps


@pytest.mark.slow
def test_a_stopped_trainer_leaves_nothing_for_long_and_resumes_from_its_last_checkpoint(tmp_path):
    """One run stopped twice: SIGTERM (its cleanup runs: a checkpoint, nothing left), resumed, then SIGKILL (no
    cleanup: its pipe directories stay, `clean` lists them, the next start sweeps them), resumed to its end."""
    run = tmp_path / "runs" / "cut"
    env = _private_env(tmp_path)
    proc = subprocess.Popen(_train_cmd("cut"), cwd=tmp_path, env=env, stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT, text=True)  # fmt: skip
    _wait_for(lambda: len(_checkpoints(run)) >= 2, 600, "two checkpoints", proc)
    out = _stop(proc, signal.SIGTERM)
    assert proc.returncode == 130 and "checkpoint saved" in out, out
    assert _pipe_dirs_of(proc.pid, env) == set()
    last = _checkpoints(run)[-1]

    # resumed, then SIGKILLed once it has saved a checkpoint of its own
    cmd = _train_cmd("cut")[:-3] + ["--resume", "runs/cut", "--quiet"]
    killed = subprocess.Popen(cmd, cwd=tmp_path, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    first = int(last.stem.split("_")[1])
    _wait_for(lambda: int(_checkpoints(run)[-1].stem.split("_")[1]) > first, 600, "a checkpoint after the resume",
              killed)  # fmt: skip
    err = _stop(killed, signal.SIGKILL)
    assert killed.returncode == -signal.SIGKILL
    _resumed_from(err, last)
    last = _checkpoints(run)[-1]
    left = _pipe_dirs_of(killed.pid, env)
    assert left, "a SIGKILLed trainer runs no cleanup: its pipe directories stay until the next start"
    assert all(leftovers.owner_alive(Path(env["TMPDIR"], d)) is False for d in left)
    listed = subprocess.run(_cli("clean", "--dry-run"), env=env, capture_output=True, text=True, check=True).stdout
    assert all(d in listed for d in left), listed

    steps = int(last.stem.split("_")[1])
    cmd = _train_cmd("cut", steps + 192)[:-3] + ["--resume", "runs/cut", "--quiet"]
    resumed = subprocess.Popen(cmd, cwd=tmp_path, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    _, err = resumed.communicate(timeout=300)
    assert resumed.returncode == 0, err
    assert _resumed_from(err, last) == steps
    assert _pipe_dirs_of(killed.pid, env) == set()  # the resumed run's first pipe swept the dead run's
    assert _pipe_dirs_of(resumed.pid, env) == set()
    assert our_processes() == []
    assert pd.read_csv(run / "episodes.csv")["timesteps"].max() > steps


@pytest.mark.slow
def test_a_trainer_killed_while_energyplus_is_stopped_leaves_a_process_that_clean_lists(tmp_path):
    run = tmp_path / "runs" / "frozen"
    env = _private_env(tmp_path)
    proc = subprocess.Popen(_train_cmd("frozen"), cwd=tmp_path, env=env, stdout=subprocess.DEVNULL,
                            stderr=subprocess.DEVNULL)  # fmt: skip
    try:
        # Two workers, each with a template per weather its episodes are forked from (engine/episodes/fork.py) and a
        # long-lived process for what was prepared before a template parked (engine/episodes/prepared.py)
        _wait_for(lambda: (run / "episodes.csv").exists() and len(_energyplus_children(proc.pid)) >= 4, 600,
                  "a finished episode and four EnergyPlus-side processes", proc)  # fmt: skip
        # Freeze the trainer first: from here it starts no worker and reaps none, so the list below holds
        # (a worker that finishes meanwhile stays a zombie, skipped; the rest cannot end their episodes).
        os.kill(proc.pid, signal.SIGSTOP)
        wait_for_state(proc.pid, "T", 10)
        workers = _energyplus_children(proc.pid)
        stopped = next(p for p in workers if process_state(p) not in ("", "Z"))
        os.kill(stopped, signal.SIGSTOP)  # stopped: it cannot notice that its trainer is gone
        wait_for_state(stopped, "T", 10)
    finally:
        proc.kill()
        proc.wait()
    _wait_for(lambda: [p.pid for p in leftovers.leftover_processes() if p.pid in workers] == [stopped],
              60, "only the stopped worker left")  # fmt: skip
    listed = subprocess.run(_cli("clean", "--dry-run"), env=env, capture_output=True, text=True, check=True).stdout
    assert f"leftover EnergyPlus process {stopped}" in listed and "clean --kill" in listed
    # `clean --kill` would also stop other users' leftovers on this shared machine: stop ours by PID.
    os.kill(stopped, signal.SIGKILL)
    _wait_for(lambda: our_processes() == [], 60, "the stopped worker gone")
    cleaned = subprocess.run(_cli("clean"), env=env, capture_output=True, text=True, check=True).stdout
    assert "removed pipe directory" in cleaned
    assert _pipe_dirs_of(proc.pid, env) == set()


@pytest.mark.slow
def test_energyplus_killed_or_stopped_during_training_restarts_and_the_run_completes(
    tmp_path, no_leaks, caplog, monkeypatch
):
    # both workers struck mid-way through their second one-day episode, after they reported step 10 (strikes.py):
    # worker 0's EnergyPlus killed, worker 1's stopped (its 2 s step timeout ends it)
    cfg = small_config(tmp_path, "hit", weathers=["CA"], run_days=1, timesteps=768, batch_size=192, step_timeout_s=2,
                       keep_episodes=1)  # fmt: skip
    killed = strike_after_step(monkeypatch, signal.SIGKILL, worker="0", episode=2, step=10)
    stopped = strike_after_step(monkeypatch, signal.SIGSTOP, worker="1", episode=2, step=10)
    final = train(cfg, progress=False)
    assert killed and stopped, "an EnergyPlus process was not struck"
    assert "worker 0: EnergyPlus failed" in caplog.text and "worker 1: EnergyPlus failed" in caplog.text
    assert "restarting its episode" in caplog.text
    assert final.is_file() and pd.read_csv(final.parent / "episodes.csv")["timesteps"].max() >= 768 - 2 * 96
    # The struck episodes keep their evidence whole, whatever --keep-episodes prunes: why, and EnergyPlus's own log
    # (on a loaded machine a 2 s step timeout may restart another episode too: the struck ones are those asked about)
    failures = sorted((final.parent / "episodes").glob("worker-*/episode-*/failure.txt"))
    for worker, why in (("0", "EnergyPlus died"), ("1", "within 2 s")):
        failure = final.parent / "episodes" / f"worker-{worker}" / "episode-000002-CA" / "failure.txt"
        assert failure in failures, failures
        assert why in failure.read_text() and (failure.parent / "eplusout.err").is_file()


@pytest.mark.slow
def test_the_restart_budget_exhausted_ends_the_run_naming_worker_weather_and_log_after_a_checkpoint(
    tmp_path, no_leaks, monkeypatch
):
    cfg = small_config(tmp_path, "budget", weathers=["FL"], run_days=1, timesteps=100_000, batch_size=192,
                       checkpoint_every=100_000, max_restarts=0)  # fmt: skip
    hit = strike_after_step(monkeypatch, signal.SIGKILL, worker="1", episode=2, step=10)
    with pytest.raises(EnergyPlusError) as err:
        train(cfg, progress=False)
    assert hit, "no EnergyPlus process was struck"
    text = str(err.value)
    assert "worker 1 failed 1 times in a row on weather FL" in text
    assert "[eplusout.err]" in text  # the tail of EnergyPlus's own error file
    [checkpoint] = _checkpoints(tmp_path / "runs" / "budget")  # saved when the run stopped
    assert int(checkpoint.stem.split("_")[1]) >= 192  # the first batch (96 steps a worker) was done
