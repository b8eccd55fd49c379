"""Which run a `train` call continues or claims, from which checkpoint and with which settings.

A new run claims its name (run_names.py); a resumed one takes its own config.json, with only where it runs
changed, and continues in the folder it is in now. Both write config.json before any EnergyPlus starts.
"""

from __future__ import annotations

import logging
import os
from pathlib import Path

import pandas as pd

from parallel_eplus import io
from parallel_eplus.buildings.building import Building, load_building
from parallel_eplus.runs.checkpoints import resume_point
from parallel_eplus.runs.policy_files import _check_init_from, run_dir_of
from parallel_eplus.runs.registry import process_alive
from parallel_eplus.runs.run_files import read_status, saved_steps, trim_episodes
from parallel_eplus.runs.run_names import claim_run_name
from parallel_eplus.training.config import TrainConfig

log = logging.getLogger(__name__)


def prepare_run(
    cfg: TrainConfig, resume: str | Path | None, overwrite: bool
) -> tuple[TrainConfig, Path | None, Building]:
    """The run's settings (a resumed run's own), checkpoint and building (resolved once here: its check, workers and
    evaluations read this object); a new run claims its name. Writes config.json."""
    checkpoint = None
    if resume is not None and cfg.init_from is not None:
        raise ValueError("--resume continues a run; --init-from starts a new one from a policy: pass one of them")
    if resume is not None:
        _refuse_a_live_run(Path(resume))
        checkpoint = _resume_point(Path(resume))
        saved = TrainConfig.from_json((run_dir_of(checkpoint) / "config.json").read_text())
        saved.continue_in(run_dir_of(checkpoint))
        steps = saved_steps(checkpoint)
        if dropped := trim_episodes(run_dir_of(checkpoint) / "episodes.csv", steps):  # killed after its last save
            log.info("episodes.csv: %d episode(s) after step %d dropped: the run collects them again", dropped, steps)
        # The run keeps its settings (the rollout buffer is sized by them); only where it runs may change.
        saved.timesteps = cfg.timesteps or saved.timesteps
        saved.backend, saved.ray_address, saved.lockstep = cfg.backend, cfg.ray_address, cfg.lockstep
        saved.overlap = cfg.overlap
        if cfg.evaluation.every:  # evaluation may be added to (or changed for) a resumed run
            saved.evaluation = cfg.evaluation
        cfg = saved
    building = load_building(cfg.building)
    cfg = cfg.resolved(building)
    if cfg.init_from is not None and checkpoint is None and cfg.algorithm != "mbpo":  # resumed: has its weights
        _check_init_from(Path(cfg.init_from), (cfg.time_features, cfg.schedule_features))  # before EnergyPlus starts
    if checkpoint is None:
        cfg.check_new_run()
        claim_run_name(cfg.run_dir, Path(cfg.tensorboard_dir) / str(cfg.run_name), overwrite)
    run_dir = cfg.run_dir
    run_dir.mkdir(parents=True, exist_ok=True)
    io.write_text(run_dir / "config.json", cfg.to_json())
    return cfg, checkpoint, building


def _refuse_a_live_run(path: Path) -> None:
    """Two trainers in one run folder would interleave its checkpoints, episodes and status: the second one stops."""
    run_dir = path if (path / "config.json").is_file() else run_dir_of(path)
    status = read_status(run_dir) or {}
    if status.get("state") == "running" and status.get("pid") != os.getpid() and process_alive(status):
        raise ValueError(
            f"{run_dir} is still being trained (pid {status.get('pid')}): wait for it, or stop it first "
            f"(`parallel-eplus runs stop {run_dir.name}`), then --resume"
        )


def _resume_point(path: Path) -> Path:
    """The checkpoint `--resume` names: an SB3 save, or a model-based run's (control/checkpoint.py)."""
    config = (path if path.is_dir() else run_dir_of(path)) / "config.json"
    if config.is_file() and TrainConfig.from_json(config.read_text()).algorithm == "mpc":
        from parallel_eplus.learning.model_based.control.checkpoint import newest_checkpoint

        return newest_checkpoint(path)
    return resume_point(path)


def episodes_done(episodes_csv: Path, workers: int) -> list[int]:
    """Finished episodes per worker so far (a resumed run continues each worker's weather cycle)."""
    if not episodes_csv.is_file():
        return [0] * workers
    counts = pd.read_csv(episodes_csv, usecols=["worker"])["worker"].value_counts()
    return [int(counts.get(i, 0)) for i in range(workers)]
