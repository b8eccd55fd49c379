"""Damaged checkpoints, a full disk and mismatched policy files: a clear error and nothing lost."""

from __future__ import annotations

import contextlib
import logging
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
from sb3_contrib import TRPO

from parallel_eplus.io import DiskFullError
from parallel_eplus.runs.checkpoints import save_checkpoint
from parallel_eplus.runs.norm_stats import read_stats
from parallel_eplus.training.config import TrainConfig
from parallel_eplus.training.train import train

from ..conftest import our_processes
from ..test_train import small_config

MODELS = Path(__file__).resolve().parents[2] / "results" / "paper" / "models"


def _steps(path: Path) -> int:
    return int(path.stem.split("_")[1])


@pytest.mark.slow
def test_a_damaged_latest_checkpoint_is_skipped_for_the_previous_one_or_refused_naming_it(tmp_path, no_leaks, caplog):
    cfg = small_config(tmp_path, "dmg", weathers=["CA"], run_days=1, timesteps=576, batch_size=192,
                       checkpoint_every=192)  # fmt: skip
    final = train(cfg, progress=False)
    run = final.parent
    checkpoints = sorted((run / "checkpoints").glob("model_*_steps.zip"), key=_steps)
    assert [_steps(c) for c in checkpoints] == [192, 384, 576]
    final.write_bytes(final.read_bytes()[:1000])  # the newest save, cut short (a crash of an older version)
    newest = checkpoints[-1]
    data = bytearray(newest.read_bytes())
    data[200:260] = b"\0" * 60  # and the newest checkpoint corrupted inside
    newest.write_bytes(bytes(data))

    # A run directory: the damaged saves are skipped, with a warning naming each and the one used.
    with caplog.at_level(logging.WARNING):
        resumed = train(TrainConfig(timesteps=768), resume=run, progress=False)
    assert f"skipping {final}" in caplog.text and f"skipping {newest}" in caplog.text
    assert f"using the previous checkpoint instead: {checkpoints[1]}" in caplog.text
    assert TRPO.load(resumed, device="cpu").num_timesteps == 768  # 384 + 2 batches

    # A damaged checkpoint named explicitly: refused, naming it and offering the previous intact one.
    stats = run / "checkpoints" / "model_vecnormalize_384_steps.npz"
    stats.write_bytes(stats.read_bytes()[:50])
    with pytest.raises(ValueError) as err:
        train(TrainConfig(), resume=checkpoints[1], progress=False)
    message = str(err.value)
    assert "\n" not in message and str(checkpoints[1]) in message and "model_vecnormalize_384_steps.npz" in message
    assert f"the previous intact one is {checkpoints[0]}" in message


@contextlib.contextmanager
def _tmpfs(path: Path, size: str):
    path.mkdir()
    mounted = subprocess.run(["mount", "-t", "tmpfs", "-o", f"size={size}", "tmpfs", str(path)], capture_output=True)
    if mounted.returncode != 0:
        pytest.skip(f"cannot mount a tmpfs here (needs root): {mounted.stderr.decode().strip()}")
    try:
        yield path
    finally:
        subprocess.run(["umount", "-l", str(path)], check=False)


def _fill(disk: Path) -> None:
    with open(disk / "filler", "wb") as f, contextlib.suppress(OSError):
        while True:
            f.write(b"\0" * 65536)
            f.flush()


@pytest.mark.slow
def test_a_full_disk_gives_a_clear_error_and_keeps_earlier_outputs_whole(tmp_path, no_leaks):
    with _tmpfs(tmp_path / "disk", "48m") as disk:
        cfg = small_config(disk, "full", weathers=["CA"], run_days=1, timesteps=192, batch_size=192)
        final = train(cfg, progress=False)
        run = final.parent
        kept = {p: p.read_bytes() for p in run.rglob("*") if p.is_file() and "episodes" not in p.parts}
        _fill(disk)

        # The run continued on the full disk: refused with one line before EnergyPlus starts.
        cmd = [sys.executable, "-m", "parallel_eplus.cli", "train", "--resume", str(run), "--timesteps", "384"]
        out = subprocess.run(cmd, cwd=tmp_path, capture_output=True, text=True, timeout=300)
        assert out.returncode == 2, out.stderr
        [line] = out.stderr.strip().splitlines()
        assert "no space left on the device writing" in line and "previous version is intact" in line

        # The final save itself on a full disk: the model and statistics keep their previous version.
        model = TRPO.load(final, device="cpu")
        norm = read_stats(run / "vecnormalize.npz")
        model.num_timesteps = 10**6  # would differ from what is on disk
        with pytest.raises(DiskFullError, match="vecnormalize.npz"):
            save_checkpoint(model, _Stats(norm), final)
        filler = disk / "filler"
        os.truncate(filler, filler.stat().st_size - 16384)  # room for the statistics, not for the model
        with pytest.raises(DiskFullError, match="model.zip"):
            save_checkpoint(model, _Stats(norm), final)
        assert TRPO.load(final, device="cpu").num_timesteps == 192
        for path, data in kept.items():
            if path.name != "vecnormalize.npz":  # rewritten whole by the second save (the same numbers)
                assert path.read_bytes() == data, path
        assert read_stats(run / "vecnormalize.npz").obs_count == norm.obs_count
        assert not list(run.rglob(".*.tmp-*")), "a temporary file was left behind"
        assert our_processes() == []


class _Stats:
    """The VecNormalize attributes save_stats reads, from saved statistics."""

    def __init__(self, s):
        from stable_baselines3.common.running_mean_std import RunningMeanStd

        self.obs_rms, self.ret_rms = RunningMeanStd(shape=s.obs_mean.shape), RunningMeanStd(shape=())
        s.fill(self.obs_rms, self.ret_rms)
        self.clip_obs, self.clip_reward, self.gamma, self.epsilon = s.clip_obs, s.clip_reward, s.gamma, s.epsilon
        self.norm_obs, self.norm_reward = s.norm_obs, s.norm_reward


def _evaluate(tmp_path: Path, caplog, *args: str) -> tuple[int, list[str]]:
    """`evaluate` in process (a fresh interpreter pays torch's import each time): its exit code and its log's lines
    from WARNING up, as its stderr shows them (a process's stderr of one line: test_bad_input.py)."""
    from parallel_eplus.cli import main

    caplog.clear()
    with contextlib.chdir(tmp_path), caplog.at_level(logging.WARNING):
        code = main(["evaluate", "--weathers", "CA", "--run-days", "1", "--workers", "1", "--out",
                     str(tmp_path / "eval"), "--quiet", *args])  # fmt: skip
    return code, "\n".join(r.getMessage() for r in caplog.records).splitlines()


def _policy(tmp_path: Path, name: str, model_from: str, stats_from: str, config_from: str) -> Path:
    d = tmp_path / name
    d.mkdir()
    shutil.copy(MODELS / model_from / "model.zip", d)
    shutil.copy(MODELS / stats_from / "vecnormalize.npz", d)
    shutil.copy(MODELS / config_from / "config.json", d)
    return d / "model.zip"


@pytest.mark.slow
@pytest.mark.parametrize(
    "model_from, stats_from, config_from, expected",
    [  # statistics of a policy with time features beside one without them, and the other way round
        ("paper-ca", "paper-ca-co-fl-time", "paper-ca", "statistics of 10 observations but model.zip observes 6"),
        ("paper-ca-co-fl-time", "paper-ca", "paper-ca-co-fl-time", "of 6 observations but model.zip observes 10"),
        # a policy for another model (2 per-zone demand corrections) with a plain policy's settings
        ("residual-demand", "residual-demand", "paper-ca", "acts on 2 values but model temp_fan takes 4"),
    ],
    ids=["stats-from-another-run", "time-features-missing", "another-model"],
)
def test_evaluate_refuses_mismatched_policy_files_before_energyplus_starts(
    tmp_path, no_leaks, caplog, model_from, stats_from, config_from, expected
):
    policy = _policy(tmp_path, "p", model_from, stats_from, config_from)
    code, err = _evaluate(tmp_path, caplog, "--policy", str(policy))
    assert code == 2, err
    lines = [ln for ln in err if "is a pickle" not in ln]
    assert len(lines) == 1 and expected in lines[0], err
    assert not (tmp_path / "eval").exists()  # nothing ran, nothing written
