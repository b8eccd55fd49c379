"""A rule-based reference that buys comfort back: every thermostat on the building's own schedule, a fixed margin
inside it (a cooling setpoint `margin_k` lower, a heating setpoint that much higher), every other action on its own
schedule.

A measure that saves energy can cost a little comfort where the zones drift: with its outdoor air on demand the
small office's zones left 2.61 occupied K.h over CA, CO and FL's 12 fortnights against its own controls' 2.56.
EnergyPlus holds a zone it can hold within 0.01 K of its setpoint, so a margin of twice that keeps it inside its
own bounds: 0.02 K, 1.92 K.h at HVAC x0.893 (on demand alone x0.890; 0.05 K: 1.51 at x0.897; 0.1 K: 1.04 at
x0.904). It cannot be computed from the observation: a schedule's value there is the step that ended, and at the
morning's jump from setback the next step's differs (set from the last one, a 0.1 K margin left 27.1 K.h). So its
actions are corrections that EnergyPlus's side adds to each actuator's own schedule at the step it applies to
(`residual_space = "builtin"`, engine/eplus_side/bridge.py), as a residual policy's are; every action therefore needs a
schedule of the building's own (`evaluate` says which lacks one).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from parallel_eplus.buildings.rules.settings import rule_config
from parallel_eplus.buildings.scaling import unit_size

SIDES = {"cooling setpoint": -1.0, "heating setpoint": 1.0}  # the way the margin moves each setpoint: inward


@dataclass
class MarginConfig:
    margin_k: float = 0.02  # K inside each thermostat's own setpoint, at every step


class OwnMargin:
    """Callable (observation, info) -> corrections to the building's own schedules, normalized: the thermostats'
    `margin_k` inward, every other action none. `evaluate --rbc parallel_eplus.buildings.rules.own_margin:OwnMargin`."""

    corrects_own = True  # its actions correct the own schedules at the step they apply to (Controller.residual)

    def __init__(self, building: str | Path | None = None, cfg: MarginConfig | None = None, target_c=None,
                 **settings):  # fmt: skip
        from parallel_eplus.buildings.building import load_building

        self.cfg = cfg or rule_config(MarginConfig, settings, "OwnMargin")  # the spec's controller_settings
        if not 0 <= self.cfg.margin_k <= 1:  # inward from both sides: past half a deadband the setpoints would cross
            raise ValueError(f"controller_settings: OwnMargin's margin_k {self.cfg.margin_k} K: within [0, 1]")
        b = load_building(building)
        correction = np.zeros(len(b.actions), dtype=np.float32)
        for i, a in enumerate(b.actions):
            sides = {SIDES.get(x.control_type.lower(), 0.0) for x in a.actuators}
            if len(sides) == 1:  # a residual's unit is half the action's range (ActionMap's at scale 1)
                correction[i] = sides.pop() * self.cfg.margin_k / unit_size(a.low, a.high)
        if not correction.any() and self.cfg.margin_k:
            raise ValueError(f"{b.spec.name}: OwnMargin moves thermostat setpoints; the spec has no action of one side "
                             "(every actuator a zone's cooling setpoint, or every one a heating setpoint)")  # fmt: skip
        self.correction = correction

    def __call__(self, obs, info: dict) -> np.ndarray:
        return self.correction.copy()
