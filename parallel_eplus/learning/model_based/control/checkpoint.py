"""The Dyna loop's checkpoints: checkpoints/mpc_<steps>_steps.pt (the planner, the step count, the comfort
multiplier, the recorded controls to replay) beside mpc_<steps>_steps.npz (every transition, and the planner's
own observations and actions for distillation). The data are written first, each file atomically, so a .pt always
has its data; the newest two are kept."""

from __future__ import annotations

import logging
import re
from pathlib import Path

import numpy as np
import torch as th

from parallel_eplus import io
from parallel_eplus.learning.model_based.model.dataset import Layout, Transitions

log = logging.getLogger(__name__)
_NAME = re.compile(r"mpc_(\d+)_steps\.pt$")


def _saves(folder: Path) -> list[Path]:
    """The planner checkpoints in `folder`, newest first."""
    found = [(int(m.group(1)), p) for p in folder.glob("mpc_*_steps.pt") if (m := _NAME.search(p.name))]
    return [p for _, p in sorted(found, reverse=True)]


def newest_checkpoint(path: Path) -> Path:
    """`path` itself (a .pt), or the newest checkpoint of a run folder whose data file is whole."""
    if path.is_file():
        return path
    io.remove_stale_temporaries(path / "checkpoints") if (path / "checkpoints").is_dir() else None
    for save in _saves(path / "checkpoints"):
        if save.with_suffix(".npz").is_file():
            return save
    raise FileNotFoundError(f"--resume: no model-based checkpoint (checkpoints/mpc_<steps>_steps.pt) in {path}")


POLICY_ARRAYS = ("policy_obs", "policy_act", "policy_prev", "policy_time", "policy_weather")


class Checkpoint:
    def __init__(self, folder: Path, keep: int = 2):
        self.folder, self.keep = folder, keep

    def save(self, steps: int, mpc, data: Transitions, extra: dict, policy) -> Path:
        self.folder.mkdir(parents=True, exist_ok=True)
        path = self.folder / f"mpc_{steps}_steps.pt"
        arrays = {f"data_{k}": data.array(k) for k in data.columns}
        if policy is not None:  # the planner's steps: observations, actions, and the action before, time, weather
            arrays |= dict(zip(POLICY_ARRAYS, policy, strict=False))
        with io.atomic_path(path.with_suffix(".npz")) as tmp, open(tmp, "wb") as f:
            np.savez(f, **arrays)
        with io.atomic_path(path) as tmp:
            th.save({"mpc": mpc.state(), **extra}, tmp)
        for old in _saves(self.folder)[self.keep :]:
            old.unlink(missing_ok=True)
            old.with_suffix(".npz").unlink(missing_ok=True)
        return path

    @staticmethod
    def load(path: Path, layout: Layout) -> tuple[dict, Transitions, tuple | None]:
        state = th.load(path, weights_only=True)
        data = Transitions(layout)
        with np.load(path.with_suffix(".npz")) as z:
            columns = {k.removeprefix("data_"): z[k] for k in z.files if k.startswith("data_")}
            if columns and len(columns["s"]):
                data.add(**columns)
            policy = tuple(z[k] for k in POLICY_ARRAYS if k in z.files) or None  # older: the first two
        return state, data, policy
