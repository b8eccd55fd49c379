"""Saving a run's models and finding one to resume from.

Every save is atomic (io.py) and writes the statistics before the model, so a model file always has
its statistics beside it. A resume checks the checkpoint first: a damaged newest checkpoint in a run
directory is skipped for the previous one (with a warning naming both); a damaged checkpoint named
explicitly is refused with the previous intact one offered.
"""

from __future__ import annotations

import logging
import zipfile
from pathlib import Path

from stable_baselines3.common.callbacks import BaseCallback

from parallel_eplus import io
from parallel_eplus.runs.norm_stats import read_stats, save_stats
from parallel_eplus.runs.policy_files import (
    normalization_file,
    replay_buffer_file,
    run_dir_of,
    saves_newest_first,
    stats_target,
)

log = logging.getLogger(__name__)


def save_checkpoint(model, env, model_zip: Path, replay_buffer: bool = False) -> Path:
    """Statistics, then the model (and SAC's replay buffer if asked), each written atomically."""
    model_zip.parent.mkdir(parents=True, exist_ok=True)
    save_stats(env, stats_target(model_zip))
    with io.atomic_path(model_zip) as tmp:
        model.save(tmp)
    if replay_buffer and hasattr(model, "save_replay_buffer"):  # off-policy (SAC)
        with io.atomic_path(replay_buffer_file(model_zip)) as tmp:
            model.save_replay_buffer(tmp)
    return model_zip


class AtomicCheckpoint(BaseCallback):
    """Every `save_freq` vector steps, model_<steps>_steps.zip and its statistics in `save_dir`."""

    def __init__(self, save_freq: int, save_dir: Path):
        super().__init__()
        self.save_freq = save_freq
        self.save_dir = save_dir

    def _on_step(self) -> bool:
        if self.n_calls % self.save_freq == 0:
            path = self.save_dir / f"model_{self.num_timesteps}_steps.zip"
            save_checkpoint(self.model, self.model.get_vec_normalize_env(), path)
            log.debug("checkpoint saved: %s", path)
        return True


def problem(model_zip: Path) -> str | None:
    """Why a saved model or checkpoint cannot be resumed from, or None if it looks whole."""
    try:
        with zipfile.ZipFile(model_zip) as z:
            damaged = z.testzip()
            names = set(z.namelist())
    except (zipfile.BadZipFile, OSError, EOFError) as e:
        return f"not a readable model file ({e})"
    if damaged is not None:
        return f"damaged ({damaged} fails its checksum)"
    if not {"data", "policy.pth"} <= names:
        return "not an SB3 model (no data or policy.pth inside)"
    stats = normalization_file(model_zip)
    if not stats.is_file() or stats.stat().st_size == 0:
        return f"its statistics {stats.name} are missing or empty"
    if stats.suffix == ".npz":  # cheap to read in full (a legacy .pkl is read, with its warning, on resume)
        try:
            read_stats(stats)
        except ValueError as e:
            return str(e)
    return None


def resume_point(path: Path) -> Path:
    """The checkpoint to resume from: `path` itself, or the newest intact save in a run directory."""
    if path.is_file() or path.suffix == ".zip":
        if not path.is_file():
            raise FileNotFoundError(f"--resume: no such checkpoint: {path}")
        why = problem(path)
        if why is None:
            return path
        saves = saves_newest_first(run_dir_of(path))
        older = saves[saves.index(path) + 1 :] if path in saves else saves
        earlier = [p for p in older if problem(p) is None]
        offer = f"the previous intact one is {earlier[0]}: pass it to --resume" if earlier else "none earlier is intact"
        raise ValueError(f"--resume {path}: {why}; {offer}")
    if not path.is_dir():
        raise FileNotFoundError(f"--resume: no such run directory or checkpoint: {path}")
    for folder in (path, path / "checkpoints"):  # half-written files of a run killed mid-save
        io.remove_stale_temporaries(folder)
    saves = saves_newest_first(path)
    if not saves:
        raise FileNotFoundError(f"--resume: no checkpoint or model.zip in {path}")
    skipped = []
    for save in saves:
        why = problem(save)
        if why is None:
            for bad, reason in skipped:
                log.warning("--resume: skipping %s: %s", bad, reason)
            if skipped:
                log.warning("--resume: using the previous checkpoint instead: %s", save)
            return save
        skipped.append((save, why))
    raise ValueError(f"--resume {path}: no intact checkpoint; the newest, {saves[0]}, is {skipped[0][1]}")
