"""`--mpc comfort_level=baseline`: the comfort target held at the building's own controls' level, date by date.

A fixed `--comfort-target` asks every building for the same share of zone samples in band. The warehouse's own
controls keep 93 % of its zone samples in their own bounds over a year, 99.95 % in winter and 77.6 % in summer
(its bulk storage has no cooling). A 99.8 % target cannot be reached there in summer, so the multiplier sat at its
cap from 12k steps on, and any predicted discomfort beyond the own plan outweighed any saving.

With this level, the share a batch may leave out of band is the larger of the target's (100 − target) and the
share the own controls left out on the same steps of the year and weathers. That share comes from the record the
run starts with (sources.py), counted as the Dyna loop counts the planner's (`Comfort.outside`: the step's bounds
widened by the spec's tolerance, where the band applies).
"""

from __future__ import annotations

import datetime as dt
from dataclasses import dataclass

import numpy as np

from parallel_eplus.buildings.weather.files import weather_label

_UNKNOWN = -1  # not recorded, or the band did not apply then


@dataclass
class OwnLevel:
    """Zones out of band under the building's own controls, per weather and step of the year."""

    step_minutes: int
    zones: int  # zones counted per step where the band applies
    out: dict[str, np.ndarray]  # [366 × steps per day] int8: zones out of band; -1 unknown

    @classmethod
    def from_record(cls, demos, sensors: list[str], temperatures: list[str], comfort, applies_of,
                    steps_per_day: int) -> OwnLevel:  # fmt: skip
        """From `record_baseline`'s demonstrations, whose observations start with `sensors`; `temperatures`: the
        zones' sensors; `applies_of(time, sensor values)`: whether the band applied to the step ending then."""
        level = cls(1440 // steps_per_day, len(temperatures), {})
        labels = np.array(demos.weathers)
        for weather in dict.fromkeys(demos.weathers):
            out = np.full(366 * steps_per_day, _UNKNOWN, np.int8)
            for r in np.flatnonzero(labels == weather):
                values = dict(zip(sensors, demos.observations[r][: len(sensors)].tolist(), strict=True))
                if not applies_of(demos.times[r], values):
                    continue
                bounds = None if demos.bounds is None else [tuple(b) for b in demos.bounds[r].tolist()]
                temps = tuple(values[t] for t in temperatures)
                out[level._step(demos.times[r]) % len(out)] = comfort.outside(temps, bounds)
            level.out[weather_label(weather)] = out
        return level

    def _step(self, t: dt.datetime) -> int:
        return ((t.timetuple().tm_yday - 1) * 1440 + t.hour * 60 + t.minute) // self.step_minutes

    def count(self, weather: str, t: dt.datetime) -> int | None:
        """Zones the own controls left out of band at the step ending at `t` on `weather`; None: unknown there."""
        out = self.out.get(weather_label(weather))
        if out is None:
            return None
        value = int(out[self._step(t) % len(out)])
        return None if value == _UNKNOWN else value

    def allowed_pct(self, target_pct: float, own_out: float, own_zones: float, unmatched: float = 0.0) -> float:
        """The share of zone samples a batch may leave out of band: the target's, or the own controls' where that
        is larger. `own_out` of `own_zones`: the own controls' on the batch's matched steps; `unmatched`: the
        batch's zone samples on steps the record does not know, counted at the target's share, so a batch only
        partly matched is not allowed the matched part's share over all of it."""
        allowed = 100.0 - target_pct
        zones = own_zones + unmatched
        return allowed if own_zones <= 0 else max(allowed, 100.0 * (own_out + allowed / 100.0 * unmatched) / zones)

    def state(self, tensors: bool = False) -> dict:
        """Plain data; `tensors`: the arrays as torch tensors (a checkpoint loaded with `weights_only`)."""
        if tensors:
            import torch as th

            out = {w: th.as_tensor(a) for w, a in self.out.items()}
        else:
            out = dict(self.out)
        return {"step_minutes": self.step_minutes, "zones": self.zones, "out": out}

    @classmethod
    def from_state(cls, state: dict) -> OwnLevel:
        return cls(int(state["step_minutes"]), int(state["zones"]),
                   {w: np.asarray(a, dtype=np.int8) for w, a in state["out"].items()})  # fmt: skip


@dataclass
class BatchComfort:
    """The zone samples out of band in one Dyna batch (the planner's, and the own controls' on the same steps), from
    which the multiplier is updated at each refit."""

    out: float = 0.0  # the planner's zone samples out of band
    zones: float = 0.0  # the planner's zone samples where the band applied
    own_out: float = 0.0  # the own controls' zone samples out on the matched steps
    own_zones: float = 0.0
    unmatched: float = 0.0  # the planner's zone samples on steps the own record does not know

    def add(self, out: int, zones: int, own: int | None, level: OwnLevel | None) -> None:
        """One step where the band applied: `out` of `zones` out of band; `own`: the own controls' count there."""
        self.out, self.zones = self.out + out, self.zones + zones
        if own is not None:
            self.own_out, self.own_zones = self.own_out + own, self.own_zones + zones
        elif level is not None:
            self.unmatched += zones

    def allowed_pct(self, target_pct: float, level: OwnLevel | None) -> float | None:
        """The batch's allowed share out of band (`OwnLevel.allowed_pct`); None without an own level."""
        return level.allowed_pct(target_pct, self.own_out, self.own_zones, self.unmatched) if level else None
