"""Deprecated alias of `parallel_eplus.learning.sb3_adapter` (moved in 0.3; removed in 0.4).

Kept one release so code written against the old path, and checkpoints whose pickles name it, still load.
"""

import warnings

from parallel_eplus.learning.sb3_adapter import SB3VecEnv

warnings.warn(
    "parallel_eplus.training.sb3_adapter moved to parallel_eplus.learning.sb3_adapter; the old path goes in 0.4",
    DeprecationWarning,
    stacklevel=2,
)

__all__ = ["SB3VecEnv"]
