"""A rule-based controller: the reference a learned policy must beat.

Per zone: supply air at its 10 C floor (colder inlet air cuts IT power more than it costs in
cooling); fan flow from feed-forward on the model's daily IT-load schedule plus an integral loop that
holds the zone just above the band's lower edge; when the flow sits at its floor and the zone is still
too cold, the setpoint rises instead. It acts through the same env as a policy (`temp_fan` model).
"""

from __future__ import annotations

import datetime as dt
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from parallel_eplus.buildings.building import Building, load_building
from parallel_eplus.buildings.datacenter import it_load_schedule
from parallel_eplus.buildings.scaling import to_unit


@dataclass
class RBCConfig:
    """The controller's parameters, in one place (tuned on CO's January, never on IL or VA)."""

    target_c: float = 22.7  # just above the 22 C lower edge of the 22-25 C band
    setpoint_floor_c: float = 10.0
    flow_per_load_kg_s: tuple[float, float] = (3.7, 4.1)  # West, East feed-forward at full IT load
    gain_kg_s_per_k: float = 0.06  # integral gain: flow demand added per K of zone error each step
    setpoint_k_per_kg_s: float = 4.0  # below the flow floor, demand turns into a warmer setpoint
    schedule: tuple[tuple[float, float], ...] = field(default_factory=it_load_schedule)


# A residual policy in demand space (`SimulationConfig.residual_space`) adds one correction per zone to
# the controller's flow demand: one continuous knob, which no clipping of a single actuator can swallow.
DEMAND_CORRECTIONS = ("west_demand_kg_s", "east_demand_kg_s")


class RuleBasedController:
    """Callable (observation, info) -> normalized action; a split-range integral loop per zone.

    One integral "flow demand" per zone: above the fan's floor it is the fan flow (setpoint at its
    floor); below it, the shortfall raises the setpoint instead.
    """

    def __init__(self, cfg: RBCConfig | None = None, building: str | Path | Building | None = None):
        """`building`: a spec with the data center's shape, or its `Building` resolved (None: the data center's own)."""
        self.cfg = cfg or RBCConfig()
        b = load_building(building)
        if len(b.actions) != 4 or len(b.temperatures) != 2:
            raise ValueError(
                f"the rule-based controller drives two zones' supply setpoints and fans (4 actions, 2 reward "
                f"temperatures); building {b.spec.name} has {len(b.actions)} and {len(b.temperatures)}"
            )
        self.temperatures = b.temperatures
        self.trim = np.zeros(2)  # integral part of the flow demand, kg/s
        self.low = np.array([a.low for a in b.actions])
        self.high = np.array([a.high for a in b.actions])

    def load(self, t: dt.datetime) -> float:
        hour = t.hour + t.minute / 60
        return next((v for until, v in self.cfg.schedule if hour < until), self.cfg.schedule[-1][1])

    def __call__(self, obs: np.ndarray, info: dict, demand_correction: np.ndarray | None = None) -> np.ndarray:
        """`demand_correction` (kg/s per zone) shifts this step's demand but not the integral state:
        the loop still settles the zones on its target, so a correction acts on transients."""
        c = self.cfg
        fan_lo, fan_hi = self.low[2], self.high[2]
        error = np.array([info[name] for name in self.temperatures]) - c.target_c  # > 0: too warm
        feed_forward = np.array(c.flow_per_load_kg_s) * self.load(info["time"])
        max_shortfall = (self.high[0] - c.setpoint_floor_c) / c.setpoint_k_per_kg_s
        self.trim = np.clip(
            self.trim + c.gain_kg_s_per_k * error, fan_lo - max_shortfall - feed_forward, fan_hi - feed_forward
        )
        demand = feed_forward + self.trim
        if demand_correction is not None:
            demand = demand + demand_correction
        flow = np.clip(demand, fan_lo, fan_hi)
        setpoint = c.setpoint_floor_c + c.setpoint_k_per_kg_s * np.maximum(fan_lo - demand, 0.0)
        physical = np.concatenate([setpoint, flow])
        return to_unit(physical, self.low, self.high).astype(np.float32)
