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

The reset itself (`advance`) reads names and numbers only (`ResetPoints`, resolved once from the building), so a
served planner riding it (deploy/serve/planner_runtime.py) runs the same arithmetic from its contract, numpy only.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from parallel_eplus.buildings.rules.settings import rule_config
from parallel_eplus.buildings.scaling import to_unit

OUTDOOR = "site outdoor air drybulb temperature"
NAME = "ASHRAE Guideline 36 supply-air temperature reset"


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


@dataclass(frozen=True)
class ResetPoints:
    """What the reset reads (by sensor name) and sets (by action index) in one building."""

    air: tuple[int, ...]  # the supply-air actions it sets
    zones: tuple[tuple[str, str], ...]  # per zone: its temperature, its cooling setpoint (the thermostat's schedule)
    outdoor: str
    low: tuple[float, ...]  # every action's bounds
    high: tuple[float, ...]
    steps_per_interval: int  # the reset's 2-minute intervals in one control step

    @classmethod
    def of(cls, building, cfg: ResetConfig) -> ResetPoints:
        """Resolved from a building, or why it cannot take the reset."""
        b = building
        # the loops a schedule sets (`Building.own`: a SetpointManager:Scheduled, the DOE VAV loops' 12.8 C); a loop on
        # another manager (the large hotel's DOAS on an outdoor-air reset) keeps it: the action is released
        air = [i for i, (a, plans) in enumerate(zip(b.actions, b.node_schedules, strict=True))
               if a.actuators and all(plans)]  # fmt: skip
        if not air:
            raise ValueError(
                f"{b.spec.name}: no supply-air action (a System Node Setpoint) whose own plan is a "
                "SetpointManager:Scheduled's schedule, for the reset to set"
            )
        if not b.zone_bounds:
            raise ValueError(f"{b.spec.name}: the reset reads each zone's own cooling setpoint (band = 'thermostat')")
        outdoor = [s.name for s in b.sensors if s.variable.lower() == OUTDOOR]
        if not outdoor:
            raise ValueError(f"{b.spec.name}: the reset reads the outdoor dry bulb; observe '{OUTDOOR}'")
        zones = tuple(zip(b.temperatures, (upper for _, upper in b.zone_bounds), strict=True))
        return cls(tuple(air), zones, outdoor[0], tuple(a.low for a in b.actions), tuple(a.high for a in b.actions),
                   max(1, round(60 / b.steps_per_day * 24 / cfg.interval_min)))  # fmt: skip

    @property
    def readings(self) -> list[str]:
        """Every sensor it reads, once each, in order."""
        return list(dict.fromkeys([self.outdoor, *(name for zone in self.zones for name in zone)]))


def advance(cfg: ResetConfig, points: ResetPoints, t_max: float, readings: dict) -> tuple[float, np.ndarray]:
    """One control step of the reset: (t_max after this step's trims and responds, the normalized action: the
    supply-air setpoint on `points.air`, NaN elsewhere). `readings`: the step's sensors by name."""
    beyond = -cfg.ignores
    for t, upper in points.zones:
        above = readings[t] - readings[upper]
        beyond += 3 if above > cfg.three_k else 2 if above > cfg.two_k else 1 if above > cfg.request_k else 0
    for _ in range(points.steps_per_interval):
        step = cfg.trim_k if beyond <= 0 else max(cfg.respond_k * beyond, cfg.respond_max_k)
        t_max = min(max(t_max + step, cfg.min_c), cfg.max_c)
    share = np.clip((readings[points.outdoor] - cfg.outdoor_low_c) / (cfg.outdoor_high_c - cfg.outdoor_low_c), 0, 1)
    sat = float(t_max + share * (cfg.min_c - t_max))
    physical = np.full(len(points.low), np.nan)
    physical[list(points.air)] = sat
    return t_max, to_unit(physical, points.low, points.high, clip=True).astype(np.float32)


def description(cfg: ResetConfig, points: ResetPoints) -> dict:
    """The reset as a served planner's contract carries it (`from_description` reads it back)."""
    return {"name": NAME, "config": asdict(cfg), "points": asdict(points)}


def from_description(entry: dict) -> tuple[ResetConfig, ResetPoints]:
    p = entry["points"]
    points = ResetPoints(tuple(p["air"]), tuple(tuple(z) for z in p["zones"]), p["outdoor"], tuple(p["low"]),
                         tuple(p["high"]), int(p["steps_per_interval"]))  # fmt: skip
    return ResetConfig(**entry["config"]), points


class SupplyAirReset:
    """Callable (observation, info) -> normalized action: G36's reset on each supply-air node action, NaN (the
    building's own control) on every other."""

    relinquishes = True  # its NaN elements mean "the building's own control" (the evaluation sets relinquish)

    def __init__(self, building: str | Path | None = None, cfg: ResetConfig | None = None, target_c=None,
                 **settings):  # fmt: skip
        from parallel_eplus.buildings.building import load_building

        self.cfg = cfg or rule_config(ResetConfig, settings, "SupplyAirReset")  # the spec's controller_settings
        self.points = ResetPoints.of(load_building(building), self.cfg)
        self.t_max = self.cfg.max_c  # SP0

    def __call__(self, obs, info: dict) -> np.ndarray:
        self.t_max, action = advance(self.cfg, self.points, self.t_max, info)
        return action
