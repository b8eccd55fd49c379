"""The agent's actions on their way to EnergyPlus: checked for NaN, clipped to [-1, 1], scaled to physical units,
or made corrections of another controller's (residual control)."""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import TYPE_CHECKING

import numpy as np

from parallel_eplus.buildings.crossing import thermostat_pairs, uncrossed
from parallel_eplus.buildings.scaling import denormalize, unit_size

if TYPE_CHECKING:
    from parallel_eplus.engine.setup import WorkerSetup


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
    return [denormalize(v, lo, hi) for v, lo, hi in zip(a, low, high, strict=True)]


def released(action, low: Sequence[float], high: Sequence[float], names: tuple[str, ...]) -> list[float]:
    """`scale_action` where NaN is kept: that element is released to the building's own control (relinquish)."""
    a = np.asarray(action, dtype=np.float64).reshape(-1)
    free = np.isnan(a)
    scaled = scale_action(np.where(free, 0.0, a), low, high, names)
    return [math.nan if f else v for f, v in zip(free.tolist(), scaled, strict=True)]


class ActionMap:
    """What a policy's action means on its way to EnergyPlus, per `SimulationConfig.residual_space`: the action
    itself, scaled to [low, high]; with a residual scale, a correction of the rule-based controller's action
    ("action") or of its flow demand ("demand"); or ("builtin") corrections, in physical units, which EnergyPlus's
    side adds to the building's own setpoint schedules at the step they apply to (bridge.py)."""

    def __init__(self, setup: WorkerSetup) -> None:
        config, elements = setup.config, setup.elements
        self.names, self.policy_names = tuple(e.name for e in elements), setup.policy_names
        self.low, self.high = tuple(e.low for e in elements), tuple(e.high for e in elements)
        self.scale, self._demand = config.residual_scale, config.residual_space == "demand"
        self._own = tuple(own[0] for own in setup.building.own) if setup.builtin_residual else None
        self._own_step = tuple(self.scale * unit_size(e.low, e.high) for e in elements)  # a unit of correction
        self._setup = setup
        self._release = setup.config.relinquish  # NaN: that element released to the building's own control
        self.base = None  # the rule-based controller a residual action corrects (`start`)
        self._pairs = thermostat_pairs(elements)  # a zone's heating setpoint kept at or below its cooling one (the
        # step's record shows what was sent): EnergyPlus stops the run on a crossed thermostat

    def start(self) -> None:
        """A new episode: a fresh rule-based controller (its integral state) where a residual corrects one."""
        self.base = self._setup.residual_base()

    def frame(self, action, info: dict) -> list[float]:
        """The values sent to EnergyPlus for `action` given the last observation's `info`."""
        if self._own is not None:
            return [v * k for v, k in zip(check_action(action, self.policy_names), self._own_step, strict=True)]
        if self._release:
            return uncrossed(released(action, self.low, self.high, self.names), self._pairs)
        if self.base is None:
            return uncrossed(scale_action(action, self.low, self.high, self.names), self._pairs)
        correction = self.scale * np.array(check_action(action, self.policy_names))
        if self._demand:  # one correction per zone, to the controller's split-range flow demand
            return scale_action(self.base(None, info, demand_correction=correction), self.low, self.high, self.names)
        return scale_action(self.base(None, info) + correction, self.low, self.high, self.names)

    def applied(self, sent: list[float], info: dict) -> list[float]:
        """What the step applied, for its record: the values sent, or (builtin) each action's schedule in that step
        (its first actuator's) plus the correction, within bounds, as bridge.py computed it."""
        if self._own is None:
            return sent
        bounds = zip(self._own, sent, self.low, self.high, strict=True)
        return [min(max(info[o] + c, lo), hi) for o, c, lo, hi in bounds]
