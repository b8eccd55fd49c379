"""A run name belongs to one run: a new run never writes into an existing run's folders.

Re-using a name used to replace the earlier model, append to its episodes.csv and interleave the two
runs' TensorBoard curves. Now a new run with a taken name is refused, saying how to continue it
(`--resume`) or start fresh (`--overwrite` moves the old run and its TensorBoard folder aside, to
`<name>.old-<time>`; nothing is deleted).
"""

from __future__ import annotations

import logging
import os
import time
from pathlib import Path

from parallel_eplus.errors import RunExistsError

log = logging.getLogger(__name__)


def _shown(path: Path) -> str:
    """`path` as a user would type it here: relative to the working directory when inside it."""
    rel = os.path.relpath(path)
    return path.as_posix() if rel.startswith("..") else rel


def claim_run_name(run_dir: Path, tensorboard_dir: Path, overwrite: bool = False) -> list[Path]:
    """Refuse (or with `overwrite`, move aside) an existing run of the same name; returns what was moved.

    `run_dir` is runs/<name>, `tensorboard_dir` the run's own TensorBoard folder (tensorboard_logs/<name>)."""
    folders = [run_dir, tensorboard_dir]
    taken = [p for p in folders if p.exists() and (not p.is_dir() or any(p.iterdir()))]
    if not taken:
        return []
    if not overwrite:
        raise RunExistsError(
            f"run {run_dir.name!r} exists ({_shown(taken[0])}): continue it with --resume {_shown(run_dir)}, "
            "or start fresh with another --run-name or --overwrite (moves the old run aside, deletes nothing)"
        )
    stamp = time.strftime("%Y%m%d-%H%M%S")
    moved = []
    for p in taken:
        aside = p.with_name(f"{p.name}.old-{stamp}")
        n = 1
        while aside.exists():
            n += 1
            aside = p.with_name(f"{p.name}.old-{stamp}-{n}")
        p.rename(aside)
        log.warning("--overwrite: moved %s aside to %s", p, aside)
        moved.append(aside)
    return moved
