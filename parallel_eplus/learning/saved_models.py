"""Opening a saved SB3 model (`--resume`, `--init-from`, `evaluate --online`), checkpoints from before 1.0 included.

SB3's `load` unpickles the model's objects by module path, and a checkpoint saved by 0.2 names modules that moved in
0.3 (`parallel_eplus.training.lagrangian`: the comfort multiplier and its rollout buffer). The old import paths are
gone in 1.0 (CHANGELOG.md, docs/contributing.md's deprecation policy), but the files people trained stay readable:
while one loads, each old path answers with the module it moved to, and is removed again afterwards.
"""

from __future__ import annotations

import importlib
import sys
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

MOVED = {  # the module path a checkpoint's pickle may name -> where that code lives now
    "parallel_eplus.training.lagrangian": "parallel_eplus.learning.lagrangian",
    "parallel_eplus.training.sb3_adapter": "parallel_eplus.learning.sb3_adapter",
}


@contextmanager
def moved_modules() -> Iterator[None]:
    """While unpickling: the old module paths resolve to the new modules; outside it they do not import."""
    added = [old for old in MOVED if old not in sys.modules]
    for old in added:
        sys.modules[old] = importlib.import_module(MOVED[old])
    try:
        yield
    finally:
        for old in added:
            sys.modules.pop(old, None)


def load_model(algorithm: type, path: Path | str, **kwargs: Any) -> Any:
    """`algorithm.load(path, **kwargs)` (an SB3 class), reading checkpoints saved under the old module paths too."""
    with moved_modules():
        return algorithm.load(path, **kwargs)
