"""A rule-based reference for a tariff's peak: pre-cool before its dearest demand window, then let the thermostats
rise back to their own setpoints through it, so the building's mass carries part of the window's cooling.

What a learned controller must beat under demand charges and time-of-use prices is not the building's constant
schedules but the strategy the field studies of pre-cooling test (Braun 2003; Xu et al. 2004 and 2006, "linear
reset"): on the days the window applies, each thermostat's cooling setpoint is `depth_k` below its own from
`lead_h` hours before the window opens, then rises linearly to its own by the window's end. The window is the
tariff's demand charge with the highest price among those with hours (the example tariff's summer peak, weekdays
12-18 h, May-October); its days and hours come from the tariff, one place. Everything else (heating setpoints,
cooling setpoints at other times, every other action) is released to the building's own schedules (NaN:
`SimulationConfig.relinquish`). Its parameters are the studies' usual ones, set before any run, not tuned.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from parallel_eplus.buildings.rules.settings import rule_config
from parallel_eplus.buildings.scaling import to_unit

COOLING = "cooling setpoint"


@dataclass
class PreCoolConfig:
    depth_k: float = 2.0  # below the own cooling setpoint while pre-cooling
    lead_h: float = 4.0  # hours of pre-cooling before the window opens


class PreCool:
    """Callable (observation, info) -> normalized action: each thermostat's cooling setpoint pre-cooled and reset
    around the tariff's dearest demand window, NaN (the building's own control) everywhere else."""

    relinquishes = True

    def __init__(self, building: str | Path | None = None, cfg: PreCoolConfig | None = None, target_c=None,
                 **settings):  # fmt: skip
        from parallel_eplus.buildings.building import load_building

        self.cfg = cfg or rule_config(PreCoolConfig, settings, "PreCool")  # the spec's controller_settings
        b = load_building(building)
        tariff = b.comfort.kpis.tariffs["Electricity"]
        timed = [d for d in tariff.demand if d.window.hours is not None and len(d.window.hours) == 1]
        if not timed:
            raise ValueError(f"{b.spec.name}: pre-cooling needs a demand charge with one window of hours in "
                             "[kpis] tariff (docs/kpis.md)")  # fmt: skip
        self.window = max(timed, key=lambda d: d.price).window
        # per cooling-setpoint action: its index and the hidden sensors reading its actuators' own schedules
        self.cooling = [
            (i, list(own))
            for i, (a, own) in enumerate(zip(b.actions, b.own, strict=True))
            if a.actuators and all(own) and all(x.control_type.lower() == COOLING for x in a.actuators)
        ]
        if not self.cooling:
            raise ValueError(f"{b.spec.name}: no thermostat cooling-setpoint action with its own schedule to pre-cool")
        self.low = np.array([a.low for a in b.actions])
        self.high = np.array([a.high for a in b.actions])

    def offset(self, t) -> float:
        """K below the own cooling setpoint for the step starting at `t`: `depth_k` in the lead hours, falling
        linearly to 0 at the window's end, 0 on other days and hours."""
        ((start, end),) = self.window.hours
        day = (self.window.weekdays is None or t.weekday() in self.window.weekdays) and (
            self.window.months is None or t.month in self.window.months)  # fmt: skip
        hour = t.hour + t.minute / 60
        if not day or not start - self.cfg.lead_h <= hour < end:
            return 0.0
        return self.cfg.depth_k * (1.0 if hour < start else (end - hour) / (end - start))

    def __call__(self, obs, info: dict) -> np.ndarray:
        physical = np.full(len(self.low), np.nan)
        offset = self.offset(info["time"])
        if offset > 0:
            for i, sensors in self.cooling:
                physical[i] = min(info[s] for s in sensors) - offset
        return to_unit(physical, self.low, self.high, clip=True).astype(np.float32)
