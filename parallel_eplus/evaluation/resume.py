"""`evaluate --resume`: an interrupted sweep continues from the episodes it finished.

A year on a planner takes ~20 minutes of a core and a study runs dozens of them; a session that ends mid-sweep
must not cost the episodes already done. Each episode writes its `summary.json` (the sweep's row) only when it
ends, so a finished episode is one whose summary says `complete` for the job's weather, length, building and test
period (episodes of every `--scenario` share a controller's folder); a killed one left no such summary and runs
again. What the summary does not record, a controller's options under the same label, resuming takes on trust:
the command must be the same.
"""

from __future__ import annotations

import datetime as dt
import json
import logging
from pathlib import Path

from parallel_eplus.buildings.weather.files import weather_label
from parallel_eplus.engine.config import SimulationConfig
from parallel_eplus.engine.episode import FAILURE_FILE, SUMMARY_FILE

log = logging.getLogger(__name__)


def finished_row(controller, cfg: SimulationConfig) -> dict | None:
    """The job's newest finished episode in its folder, as the row the sweep would have made; None if none."""
    folder = Path(cfg.output_dir)
    for episode_dir in sorted(folder.glob("episode-*"), reverse=True):
        path = episode_dir / SUMMARY_FILE
        if not path.is_file() or (episode_dir / FAILURE_FILE).is_file():
            continue
        try:
            summary = json.loads(path.read_text())
        except (OSError, json.JSONDecodeError):
            continue  # cut off while written: the episode runs again
        if same_job(summary, cfg):
            return {"controller": controller.label, "run": controller.run, **summary, "episode_dir": str(episode_dir)}
    return None


def same_job(summary: dict, cfg: SimulationConfig) -> bool:
    """Whether a finished episode's summary is the job's: its weather, length, spec (by file name: a study's code
    copy moves its path) and test period (the first scored day)."""
    if summary.get("complete") is not True or summary.get("run_days") != cfg.run_days:
        return False
    if summary.get("weather") != weather_label(cfg.weather):
        return False
    if Path(str(summary.get("building", ""))).name != (Path(cfg.building).name if cfg.building else ""):
        return False
    if int(summary.get("warmup_days", 0)) != cfg.warmup_days:
        return False
    if cfg.warmup_days:  # a test period: its first scored day of the year
        try:
            first = dt.datetime.fromisoformat(str(summary.get("period_start"))).timetuple().tm_yday
        except ValueError:
            return False
        return first == (cfg.start_day - 1 + cfg.warmup_days) % 365 + 1
    return True


def split_finished(jobs: list[tuple]) -> tuple[list[dict], list[tuple]]:
    """(rows of the jobs already finished, the jobs still to run)."""
    rows, todo = [], []
    for controller, cfg in jobs:
        row = finished_row(controller, cfg)
        if row is None:
            todo.append((controller, cfg))
        else:
            rows.append(row)
    log.info("--resume: %d of %d episodes finished before, %d to run", len(rows), len(jobs), len(todo))
    return rows, todo
