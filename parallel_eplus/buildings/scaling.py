"""Physical units and the policy's [-1, 1], both ways. One formula, so that a bound means the same on every path.

`normalize`, `denormalize` and `unit_size` are the formula itself, plain arithmetic in whatever the values come in:
Python floats (the per-step path to EnergyPlus, engine/actions.py, where numpy's fixed cost per call would be most of
the work), numpy arrays of any dtype, torch tensors. `to_unit` and `from_unit` are it on float64 numpy arrays, for
the rules, the served planner, the BACnet and HTTP bridges. NaN stays NaN: an element released to the building's
own control."""

from __future__ import annotations

import numpy as np


def to_unit(physical, low, high, clip: bool = False) -> np.ndarray:
    """Physical values -> [-1, 1] over [low, high]; `clip`: clipped to the bounds first (a rule's target may lie
    beyond them)."""
    physical, low, high = np.asarray(physical, np.float64), np.asarray(low, np.float64), np.asarray(high, np.float64)
    if clip:
        physical = np.clip(physical, low, high)
    return normalize(physical, low, high)


def from_unit(action, low, high) -> np.ndarray:
    """[-1, 1] -> physical values over [low, high]."""
    low, high = np.asarray(low, np.float64), np.asarray(high, np.float64)
    return denormalize(np.asarray(action, np.float64), low, high)


def normalize(physical, low, high):
    """Physical values -> [-1, 1] over [low, high], in the values' own arithmetic (no conversion)."""
    return 2 * (physical - low) / (high - low) - 1


def denormalize(action, low, high):
    """[-1, 1] -> physical values over [low, high], in the values' own arithmetic (no conversion)."""
    return low + (action + 1) / 2 * (high - low)


def unit_size(low, high):
    """Physical units per unit of [-1, 1] over [low, high]: what a normalized correction of 1 moves (residual
    control's unit)."""
    return (high - low) / 2
