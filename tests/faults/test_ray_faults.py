"""Faults with the Ray backend: an EnergyPlus worker killed inside an actor, an actor lost with its node.

Ray runs locally here (one node); a lost node is an actor process killed outright, which is what Ray
reports when a node's raylet dies (docs/cluster.md measures the two-node case).
"""

from __future__ import annotations

import os
import signal
import subprocess
import time

import pytest

from parallel_eplus.engine.pipes import leftovers
from parallel_eplus.errors import WorkerLostError
from parallel_eplus.learning.ray_vector_env import RayVectorEnv
from parallel_eplus.training.config import TrainConfig
from parallel_eplus.training.train import train

from ..conftest import _started_by_us
from ..test_train import scalars, small_config

pytestmark = pytest.mark.slow
ray = pytest.importorskip("ray")


def _ours(pattern: str) -> list[int]:
    out = subprocess.run(["pgrep", "-f", pattern], capture_output=True, text=True)
    return [int(p) for p in out.stdout.split() if _started_by_us(p)]


def _kill_first(pattern: str, hit: list[int]) -> None:
    """SIGKILL the first of this session's processes matching `pattern`."""
    victim = _ours(pattern)[0]
    os.kill(victim, signal.SIGKILL)
    hit.append(victim)


def _before_batch(monkeypatch, batch: int, strike) -> None:
    """Run `strike()` in the learner as it orders batch `batch` (from 1), before the order goes out: every
    actor is idle then, and each of its EnergyPlus workers waits for its next action (a moment the test
    controls, not a delay)."""
    send, calls = RayVectorEnv.send, []

    def striking_send(self, order, rngs):
        calls.append(batch)
        if len(calls) == batch:
            strike()
        return send(self, order, rngs)

    monkeypatch.setattr(RayVectorEnv, "send", striking_send)


def _during_batch(monkeypatch, batch: int, strike) -> None:
    """Run `strike()` once every actor has the order for batch `batch`, before its fragments are awaited."""
    get_all, calls = RayVectorEnv._get_all, []

    def striking_get_all(self, refs, stats=None):
        if stats is not None:  # a batch's fragments (start-up and lockstep calls pass none)
            calls.append(batch)
            if len(calls) == batch:
                strike()
        return get_all(self, refs, stats)

    monkeypatch.setattr(RayVectorEnv, "_get_all", striking_get_all)


def test_an_energyplus_worker_killed_inside_an_actor_restarts_there_and_the_run_completes(
    tmp_path, no_leaks, monkeypatch
):
    # Struck as the learner orders the second batch: every actor is idle and every EnergyPlus worker waits
    # for its next action at step 160 of a 192-step episode, so the strike lands mid-episode, never by timing.
    # Long-lived processes: a forked episode shares its command line with its template, which the strike would hit
    # instead (a template's death costs no episode: tests/test_fork.py; so does a killed forked child's recovery).
    cfg = small_config(tmp_path, "hit", weathers=["CA"], run_days=2, timesteps=960, batch_size=320,
                       checkpoint_every=320, backend="ray", workers_per_actor=1, fork_episodes=False)  # fmt: skip
    hit: list[int] = []
    _before_batch(monkeypatch, 2, lambda: _kill_first(leftovers.CALLBACK_MODULE, hit))
    final = train(cfg, progress=False)
    assert hit, "no EnergyPlus process to hit"
    assert final.is_file()
    restarts = scalars(tmp_path / "tb" / "hit")["throughput/worker_restarts"]
    assert restarts[-1].value == 1  # the cut episode was restarted inside its actor, within the budget
    assert [s.value for s in scalars(tmp_path / "tb" / "hit")["ray/round_trips"]] == [2.0] * 3


def test_a_lost_actor_stops_the_run_naming_its_node_after_a_checkpoint_that_resumes(tmp_path, no_leaks, monkeypatch):
    cfg = small_config(tmp_path, "lost", weathers=["CA"], run_days=30, timesteps=100_000, batch_size=1152,
                       checkpoint_every=1152, backend="ray", workers_per_actor=1)  # fmt: skip
    checkpoints = cfg.run_dir.resolve() / "checkpoints"
    hit: list[int] = []
    _during_batch(monkeypatch, 2, lambda: _kill_first("ray::WorkerGroup", hit))  # lost with batch 2 under way
    t0 = time.monotonic()
    with pytest.raises(WorkerLostError) as err:
        train(cfg, progress=False)
    assert hit
    text = str(err.value)  # Ray reports the death, or on a machine too busy for that the progress check goes unanswered
    assert ("was lost" in text or "did not answer a progress check" in text) and "on node" in text
    assert time.monotonic() - t0 < 600
    checkpoint = max(checkpoints.glob("model_*_steps.zip"), key=lambda p: int(p.stem.split("_")[1]))
    steps = int(checkpoint.stem.split("_")[1])
    assert steps >= 1152
    resumed = train(TrainConfig(timesteps=steps + 1152), resume=checkpoint, progress=False)
    assert resumed.is_file()


def test_ctrl_c_during_ray_training_saves_a_checkpoint_and_leaves_no_ray_energyplus_or_pipes(tmp_path, no_leaks):
    import sys

    cmd = [
        sys.executable, "-m", "parallel_eplus.cli", "train", "--backend", "ray", "--workers", "2",
        "--workers-per-actor", "1", "--weathers", "CA", "--run-days", "30", "--timesteps", "100000",
        "--batch-size", "1152", "--checkpoint-every", "1152", "--run-name", "cut", "--quiet",
    ]  # fmt: skip
    proc = subprocess.Popen(cmd, cwd=tmp_path, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    checkpoints = tmp_path / "runs" / "cut" / "checkpoints"
    deadline = time.monotonic() + 600  # (a machine loaded by other runs can take minutes)
    while not (checkpoints.is_dir() and any(checkpoints.iterdir())) and proc.poll() is None:
        assert time.monotonic() < deadline, "no checkpoint within 600 s"
        time.sleep(0.5)
    time.sleep(2.0)  # most likely mid-batch; whatever the moment, the outcome below must hold
    proc.send_signal(signal.SIGINT)
    out, _ = proc.communicate(timeout=120)
    assert proc.returncode == 130, out
    assert "checkpoint saved" in out
    deadline = time.monotonic() + 30  # Ray's own processes exit on their own schedule after the trainer's
    while _ours("ray::") or _ours("raylet") or _ours("gcs_server"):
        assert time.monotonic() < deadline, (_ours("ray::"), _ours("raylet"), _ours("gcs_server"))
        time.sleep(0.2)


def test_a_failed_ray_episode_leaves_the_evaluation_standing(tmp_path, no_leaks, broken_weather):
    """The Ray sweep keeps going past a failed episode as the local one does, naming it and why."""
    from parallel_eplus.evaluation.controllers import BASELINE_LABEL, Controller
    from parallel_eplus.evaluation.sweep import run_sweep

    df = run_sweep([Controller(BASELINE_LABEL, "baseline")], ["CA", str(broken_weather)], 1, 2, tmp_path / "eval",
                   progress=False, backend="ray", keep_going=True)  # fmt: skip
    assert list(df["weather"]) == ["CA"]
    (failure,) = df.attrs["failures"]
    assert failure["weather"] == "Broken" and "Invalid Date info in Weather Line" in failure["error"]
