"""A run folder's files by name, and reading them back, without the learner's imports (torch, SB3).

`parallel-eplus runs` reads many run folders in a second from these; the trainer writes them
(policy_files.py, checkpoints.py, run_status.py).
"""

from __future__ import annotations

import contextlib
import json
import zipfile
from pathlib import Path

MODEL_FILE = "model.zip"
STATUS_FILE = "status.json"  # run_status.py
STATES = ("running", "finished", "stopped", "failed")
EVALUATIONS_FILE = "evaluations.csv"  # evaluation during training (periodic_eval.py)
TARGET_FILE = "target.json"  # when the run first met its --target
BEST_DIR = "best"  # the best-by-evaluation policy: best/model.zip and its statistics
ALL_WEATHERS = "all"  # evaluations.csv's row of means over the evaluation weathers


def latest_evaluation(run_dir: Path) -> dict | None:
    """The newest evaluation's means over its weathers (evaluations.csv), or None."""
    import pandas as pd

    try:
        df = pd.read_csv(Path(run_dir) / EVALUATIONS_FILE)
    except (OSError, ValueError):
        return None
    rows = df[df["weather"] == ALL_WEATHERS] if "weather" in df else df.iloc[0:0]
    return rows.iloc[-1].to_dict() if len(rows) else None


def read_json(path: Path) -> dict | None:
    try:
        return json.loads(Path(path).read_text())
    except (OSError, ValueError):
        return None


def saves_newest_first(run_dir: Path) -> list[Path]:
    """A run's checkpoints (SB3's model_N_steps.zip, a model-based run's mpc_N_steps.pt) and final model, the newest
    first (by steps, the final model by its time)."""
    folder = run_dir / "checkpoints"
    checkpoints = sorted([*folder.glob("model_*_steps.zip"), *folder.glob("mpc_*_steps.pt")],
                         key=lambda p: int(p.stem.split("_")[1]))  # fmt: skip
    final = run_dir / MODEL_FILE
    if final.is_file():  # after the last checkpoint when the run finished, before it when resumed past it
        newer = [c for c in checkpoints if c.stat().st_mtime_ns > final.stat().st_mtime_ns]
        checkpoints.insert(len(checkpoints) - len(newer), final)
    return checkpoints[::-1]


def saved_steps(save: Path) -> int:
    """Steps of a checkpoint (from its name: model_N_steps.zip, mpc_N_steps.pt) or of model.zip (SB3's
    `num_timesteps` in its data file); 0 if unreadable."""
    if save.name != MODEL_FILE:
        return int(save.stem.split("_")[1])
    with contextlib.suppress(OSError, ValueError, KeyError, zipfile.BadZipFile), zipfile.ZipFile(save) as z:
        return int(json.loads(z.read("data"))["num_timesteps"])
    return 0


def trim_episodes(episodes_csv: Path, steps: int) -> int:
    """Drop the rows of episodes that ended after step `steps` (a run killed after its last checkpoint: resumed
    from it, it runs those episodes again): the rows dropped."""
    import pandas as pd

    from parallel_eplus import io

    try:
        df = pd.read_csv(episodes_csv)
    except (OSError, ValueError):
        return 0
    if "timesteps" not in df or not (late := df["timesteps"] > steps).any():
        return 0
    io.write_text(episodes_csv, df[~late].to_csv(index=False))
    return int(late.sum())


def read_status(run_dir: Path) -> dict | None:
    """The run's status.json, or None if it has none (a run from before it existed) or it cannot be read."""
    try:
        status = json.loads((Path(run_dir) / STATUS_FILE).read_text())
    except (OSError, ValueError):
        return None
    return status if isinstance(status, dict) and status.get("state") in STATES else None
