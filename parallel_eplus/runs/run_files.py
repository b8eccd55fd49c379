"""A run folder's files by name, and reading them back, without the learner's imports (torch, SB3).

`parallel-eplus runs` reads many run folders in a second from these; the trainer writes them
(policy_files.py, checkpoints.py, run_status.py).
"""

from __future__ import annotations

import json
from pathlib import Path

MODEL_FILE = "model.zip"
STATUS_FILE = "status.json"  # run_status.py
STATES = ("running", "finished", "stopped", "failed")


def saves_newest_first(run_dir: Path) -> list[Path]:
    """A run's checkpoints and final model, the newest first (by steps, the final model by its time)."""
    checkpoints = sorted((run_dir / "checkpoints").glob("model_*_steps.zip"), key=lambda p: int(p.stem.split("_")[1]))
    final = run_dir / MODEL_FILE
    if final.is_file():  # after the last checkpoint when the run finished, before it when resumed past it
        newer = [c for c in checkpoints if c.stat().st_mtime_ns > final.stat().st_mtime_ns]
        checkpoints.insert(len(checkpoints) - len(newer), final)
    return checkpoints[::-1]


def read_status(run_dir: Path) -> dict | None:
    """The run's status.json, or None if it has none (a run from before it existed) or it cannot be read."""
    try:
        status = json.loads((Path(run_dir) / STATUS_FILE).read_text())
    except (OSError, ValueError):
        return None
    return status if isinstance(status, dict) and status.get("state") in STATES else None
