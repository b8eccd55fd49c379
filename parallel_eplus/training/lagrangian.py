"""Deprecated alias of `parallel_eplus.learning.lagrangian` (moved in 0.3; removed in 0.4).

Kept one release so code written against the old path, and checkpoints whose pickles name it, still load.
"""

import warnings

from parallel_eplus.learning.lagrangian import (
    ConstrainedRolloutBuffer,
    CostReplayBuffer,
    Lagrangian,
    SACComfort,
    comfort_of,
)

warnings.warn(
    "parallel_eplus.training.lagrangian moved to parallel_eplus.learning.lagrangian; the old path goes in 0.4",
    DeprecationWarning,
    stacklevel=2,
)

__all__ = ["ConstrainedRolloutBuffer", "CostReplayBuffer", "Lagrangian", "SACComfort", "comfort_of"]
