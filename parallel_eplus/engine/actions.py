"""The agent's actions on their way to EnergyPlus: checked for NaN, clipped to [-1, 1], scaled to physical units."""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np


def check_action(action, names: tuple[str, ...]) -> list[float]:
    """The action as floats clipped to [-1, 1]; NaN or inf is a ValueError naming the element.

    Per step, Python floats: numpy's fixed cost per call is most of the work on four values.
    """
    if isinstance(action, np.ndarray) and action.ndim == 1:
        a = action.tolist()
    else:
        a = np.asarray(action, dtype=np.float64).reshape(-1).tolist()
    if len(a) != len(names):
        raise ValueError(f"action must have {len(names)} elements, got shape {np.shape(action)}")
    if not all(map(math.isfinite, a)):
        i, v = next((i, v) for i, v in enumerate(a) if not math.isfinite(v))
        raise ValueError(f"action element {i} ({names[i]}) is {v}; actions must be finite")
    return [-1.0 if v < -1.0 else 1.0 if v > 1.0 else float(v) for v in a]


def scale_action(action, low: Sequence[float], high: Sequence[float], names: tuple[str, ...]) -> list[float]:
    """[-1, 1] -> physical units, clipped; NaN or inf is a ValueError naming the element."""
    a = check_action(action, names)
    return [lo + (v + 1.0) * 0.5 * (hi - lo) for v, lo, hi in zip(a, low, high, strict=True)]
