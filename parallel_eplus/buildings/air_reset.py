"""A rule-based reference for a building's air side: ASHRAE Guideline 36's supply-air temperature reset, the
thermostats left to the building's own schedules.

What a learned controller on a VAV building must beat is not the model's constant supply air (the DOE prototypes
hold 12.8 C all year) but the reset a commissioning engineer would write. Guideline 36 (2018, 5.16.2.2): the
supply-air setpoint is `t_max` at outdoor air of 16 C and below, the minimum (12.8 C) at 21 C and above, linear
between; `t_max` is trimmed and responded between the minimum and 18 C on the zones' cooling requests, every
2 minutes (+0.1 K with no more requests than those ignored, -0.2 K per request beyond them, at most -0.6 K), a
zone sending 3 requests 3 K above its cooling setpoint, 2 at 2 K and 1 while its cooling loop is saturated (here:
above its setpoint by `request_k`, as the spec observes no loop). The 2-minute intervals run within each control
step on that step's requests.

It resets the supply-air actions whose own plan is a `SetpointManager:Scheduled`'s schedule (the DOE VAV loops'
constant 12.8 C); every other action, the thermostats among them, is released (NaN: `SimulationConfig.relinquish`),
so the building's own schedules and managers set them at the step they apply to. It acts through the same env as a
policy.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from parallel_eplus.buildings.building import load_building

OUTDOOR = "site outdoor air drybulb temperature"


@dataclass
class ResetConfig:
    """Guideline 36's defaults (SI), in one place."""

    min_c: float = 12.8  # Min_ClgSAT
    max_c: float = 18.0  # Max_ClgSAT: t_max's upper end
    outdoor_low_c: float = 16.0  # at and below: t_max
    outdoor_high_c: float = 21.0  # at and above: min_c
    # G36 ignores 2 requests of an air handler's zones; one knob serves every zone here, and the score counts each
    # zone's excess: with 2 ignored, the medium office's top-floor perimeter sat above its cooling setpoint (CO,
    # January: 98.3 % in its own bounds against its own controls' 99.4 %; with none, 99.35 %)
    ignores: int = 0
    trim_k: float = 0.1
    respond_k: float = -0.2  # per request beyond the ignored
    respond_max_k: float = -0.6
    interval_min: float = 2.0
    # Requests (G36 5.6.8): 3 from a zone this far above its cooling setpoint, 2 from one this far, 1 from one
    # above it by `request_k` (its cooling loop saturated, which the spec does not observe)
    three_k: float = 3.0
    two_k: float = 2.0
    request_k: float = 0.2


class SupplyAirReset:
    """Callable (observation, info) -> normalized action: G36's reset on each supply-air node action, NaN (the
    building's own control) on every other."""

    relinquishes = True  # its NaN elements mean "the building's own control" (the evaluation sets relinquish)

    def __init__(self, building: str | Path | None = None, cfg: ResetConfig | None = None, **_):
        b = load_building(building)
        self.cfg = cfg or ResetConfig()
        # the loops a schedule sets (`Building.own`: a SetpointManager:Scheduled, the DOE VAV loops' 12.8 C); a loop on
        # another manager (the large hotel's DOAS on an outdoor-air reset) keeps it: the action is released
        self.air = [i for i, (a, plans) in enumerate(zip(b.actions, b.node_schedules, strict=True))
                    if a.actuators and all(plans)]  # fmt: skip
        if not self.air:
            raise ValueError(
                f"{b.spec.name}: no supply-air action (a System Node Setpoint) whose own plan is a "
                "SetpointManager:Scheduled's schedule, for the reset to set"
            )
        if not b.zone_bounds:
            raise ValueError(f"{b.spec.name}: the reset reads each zone's own cooling setpoint (band = 'thermostat')")
        outdoor = [s.name for s in b.sensors if s.variable.lower() == OUTDOOR]
        if not outdoor:
            raise ValueError(f"{b.spec.name}: the reset reads the outdoor dry bulb; observe '{OUTDOOR}'")
        self.outdoor = outdoor[0]
        self.zones = list(zip(b.temperatures, (upper for _, upper in b.zone_bounds), strict=True))
        self.low = np.array([a.low for a in b.actions])
        self.high = np.array([a.high for a in b.actions])
        self.n = len(b.actions)
        self.t_max = self.cfg.max_c  # SP0
        self.steps_per_interval = max(1, round(60 / b.steps_per_day * 24 / self.cfg.interval_min))

    def requests(self, info: dict) -> int:
        c, out = self.cfg, 0
        for t, upper in self.zones:
            above = info[t] - info[upper]
            out += 3 if above > c.three_k else 2 if above > c.two_k else 1 if above > c.request_k else 0
        return out

    def setpoint(self, outdoor_c: float) -> float:
        c = self.cfg
        share = np.clip((outdoor_c - c.outdoor_low_c) / (c.outdoor_high_c - c.outdoor_low_c), 0.0, 1.0)
        return float(self.t_max + share * (c.min_c - self.t_max))

    def __call__(self, obs, info: dict) -> np.ndarray:
        c = self.cfg
        beyond = self.requests(info) - c.ignores
        for _ in range(self.steps_per_interval):
            step = c.trim_k if beyond <= 0 else max(c.respond_k * beyond, c.respond_max_k)
            self.t_max = min(max(self.t_max + step, c.min_c), c.max_c)
        action = np.full(self.n, np.nan)
        sat = self.setpoint(info[self.outdoor])
        for i in self.air:
            action[i] = 2 * (min(max(sat, self.low[i]), self.high[i]) - self.low[i]) / (self.high[i] - self.low[i]) - 1
        return action.astype(np.float32)
