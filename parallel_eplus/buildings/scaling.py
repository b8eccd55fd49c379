"""Physical units and the policy's [-1, 1], both ways, for code that works on numpy arrays: the rules, the served
planner, the BACnet and HTTP bridges. One formula, so that a bound means the same on every path (the per-step path
to EnergyPlus has its own, on Python floats: engine/actions.py). NaN stays NaN: an element released to the
building's own control."""

from __future__ import annotations

import numpy as np


def to_unit(physical, low, high, clip: bool = False) -> np.ndarray:
    """Physical values -> [-1, 1] over [low, high]; `clip`: clipped to the bounds first (a rule's target may lie
    beyond them)."""
    physical, low, high = np.asarray(physical, np.float64), np.asarray(low, np.float64), np.asarray(high, np.float64)
    if clip:
        physical = np.clip(physical, low, high)
    return 2 * (physical - low) / (high - low) - 1


def from_unit(action, low, high) -> np.ndarray:
    """[-1, 1] -> physical values over [low, high]."""
    low, high = np.asarray(low, np.float64), np.asarray(high, np.float64)
    return low + (np.asarray(action, np.float64) + 1) / 2 * (high - low)
