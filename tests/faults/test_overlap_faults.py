"""Faults while the workers collect ahead of the update (`train --overlap`): Ctrl-C and a lost worker or actor,
struck at a moment the test controls, the first update's start (the next batch is then on order, its
collection running), still end with a checkpoint and nothing left running.
"""

from __future__ import annotations

import os
import signal
import subprocess
import threading

import pytest

from parallel_eplus.engine.pipes import leftovers
from parallel_eplus.errors import EnergyPlusError, WorkerLostError
from parallel_eplus.learning.algorithms import FastTRPO
from parallel_eplus.training.config import TrainConfig
from parallel_eplus.training.train import train

from ..conftest import _started_by_us, our_processes
from ..test_train import small_config

pytestmark = pytest.mark.slow
BATCH = 144  # 72 steps per worker: one-day episodes (96 steps), so the first update finds both mid-episode


def _config(tmp_path, name: str, **overrides) -> TrainConfig:
    """Overlapped training on one weather (one template per worker to start, not one per weather), for far longer
    than the test lets it run."""
    base = dict(weathers=["CA"], run_days=1, batch_size=BATCH, timesteps=20 * BATCH, checkpoint_every=10**6)
    return small_config(tmp_path, name, overlap=True, **(base | overrides))


def _strike_at_first_update(monkeypatch, strike) -> list[bool]:
    """Run `strike()` as the first update starts, while the next batch is being collected."""
    struck: list[bool] = []
    update = FastTRPO.train

    def train_then(self):
        if not struck:
            assert self._ordered_from is not None and self._ordered_from.in_flight  # collecting ahead
            struck.append(True)
            strike()
        return update(self)

    monkeypatch.setattr(FastTRPO, "train", train_then)
    return struck


def _ours(pattern: str) -> list[int]:
    out = subprocess.run(["pgrep", "-f", pattern], capture_output=True, text=True)
    return [int(p) for p in out.stdout.split() if _started_by_us(p)]


def _kill_one(pattern: str) -> None:
    os.kill(_ours(pattern)[0], signal.SIGKILL)


def _kill_all(pattern: str) -> None:
    """Every match: EnergyPlus-side processes cannot be told apart by name, and one preparing an episode is
    replaced without a failure (engine/episodes/prepared.py), so the running ones go too."""
    for pid in _ours(pattern):
        os.kill(pid, signal.SIGKILL)


def _left_running() -> list:
    return [t for t in threading.enumerate() if t.name == "parallel-eplus-collect"] + our_processes()


def _checkpoint_steps(cfg: TrainConfig) -> list[int]:
    return sorted(int(p.stem.split("_")[1]) for p in (cfg.run_dir / "checkpoints").glob("model_*_steps.zip"))


@pytest.mark.parametrize("backend", ["local", "ray"])
def test_ctrl_c_during_an_overlapped_update_saves_a_checkpoint_stops_the_collection_and_resumes(
    tmp_path, no_leaks, monkeypatch, backend
):
    if backend == "ray":
        pytest.importorskip("ray")
    cfg = _config(tmp_path, f"cut-{backend}", backend=backend, workers_per_actor=1)
    struck = _strike_at_first_update(monkeypatch, lambda: os.kill(os.getpid(), signal.SIGINT))
    with pytest.raises(KeyboardInterrupt):
        train(cfg, progress=False)
    assert struck
    assert _checkpoint_steps(cfg) == [BATCH]  # the batch learned from; the one collected ahead is dropped
    assert _left_running() == []
    if backend == "ray":
        assert _ours("ray::") == []
    monkeypatch.undo()
    resumed = train(TrainConfig(timesteps=3 * BATCH, overlap=True), resume=cfg.run_dir, progress=False)
    assert FastTRPO.load(resumed, device="cpu").num_timesteps == 3 * BATCH


def test_a_worker_lost_during_an_overlapped_update_ends_the_run_after_a_checkpoint(tmp_path, no_leaks, monkeypatch):
    cfg = _config(tmp_path, "lost", max_restarts=0)
    struck = _strike_at_first_update(monkeypatch, lambda: _kill_all(leftovers.CALLBACK_MODULE))
    with pytest.raises(EnergyPlusError, match="failed 1 times in a row"):
        train(cfg, progress=False)
    assert struck
    assert _checkpoint_steps(cfg) == [BATCH]  # reported after the update it struck, with that update kept
    assert _left_running() == []


def test_an_actor_lost_during_an_overlapped_update_ends_the_run_after_a_checkpoint(tmp_path, no_leaks, monkeypatch):
    pytest.importorskip("ray")
    cfg = _config(tmp_path, "lost-ray", backend="ray", workers_per_actor=1, batch_size=BATCH, timesteps=40 * BATCH)
    struck = _strike_at_first_update(monkeypatch, lambda: _kill_one("ray::WorkerGroup"))
    with pytest.raises(WorkerLostError, match="was lost"):
        train(cfg, progress=False)
    assert struck
    assert _checkpoint_steps(cfg) == [BATCH]
    assert _left_running() == [] and _ours("ray::") == []
    assert leftovers.stale_pipe_dirs() == []  # the lost actor ran no cleanup: its pipe directories swept at the end
