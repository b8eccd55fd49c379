"""The rule a served planner rides (`baseline_source=rule`): Guideline 36's supply-air reset, run from the contract.

In process the planner's own plan for the supply air is the reset's setpoint at each step (control.py); served, the
server keeps no state, so the reset's one number of memory (`t_max`, trimmed and responded step by step) comes
with the request (`rule_state`, the last answer's), and what the reset reads beyond the planner's sensors (each
zone's cooling setpoint) comes as `rule_readings`. The arithmetic is the rule's own (buildings/rules/air_reset.py).
The same setpoints are what a fallback sends: the rule the planner departs from, not the model's constant one.
"""

from __future__ import annotations

import math

import numpy as np

from parallel_eplus.buildings.rules.air_reset import advance, description, from_description
from parallel_eplus.deploy.serve.contract import InputError, same_unit


def rule_entry(rule, sensor_names: list[str]) -> dict:
    """The contract's `rule` block for an in-process rule (one that says what it reads: `points`), or why not."""
    if not hasattr(rule, "points"):
        raise ValueError(f"{type(rule).__name__} has no served form: only Guideline 36's supply-air reset "
                         "(parallel_eplus.buildings.rules.air_reset:SupplyAirReset) is served beside a "
                         "planner")  # fmt: skip
    extra = [n for n in rule.points.readings if n not in sensor_names]
    return {
        **description(rule.cfg, rule.points), "required": True,
        "readings": [{"name": n, "unit": "C", "meaning": "the outdoor dry bulb" if n == rule.points.outdoor else
                      "a zone's cooling setpoint in force (its thermostat's schedule)"} for n in extra],
        "state": {"name": "t_max_c", "initial": rule.cfg.max_c, "meaning": "the reset's upper supply-air "
                  "setpoint as trimmed and responded so far: the last answer's `rule_state`, sent back"},
        "meaning": "the planner departs from this rule's setpoints on the actions it sets, and falls back to them",
    }  # fmt: skip


class ServedRule:
    """One request's step of the rule: (its normalized action, NaN where it releases; its state after the step)."""

    def __init__(self, entry: dict, sensor_names: list[str]):
        try:
            self.cfg, self.points = from_description(entry)
        except (KeyError, TypeError) as e:
            raise ValueError(
                f"the contract's `rule` is not one this version reads ({e}): export the planner again"
            ) from None
        self.sensor_names = sensor_names
        self.extra = [r["name"] for r in entry["readings"]]

    def step(self, body: dict, obs: np.ndarray) -> tuple[np.ndarray, dict]:
        sensors = obs[: len(self.sensor_names)].tolist()
        readings = dict(zip(self.sensor_names, sensors, strict=True)) | self._readings(body.get("rule_readings"))
        t_max, action = advance(self.cfg, self.points, self._t_max(body.get("rule_state")), readings)
        return action, {"t_max_c": t_max}

    def _readings(self, given) -> dict[str, float]:
        if not self.extra:
            return {}
        if not isinstance(given, dict):
            raise InputError("rule_readings", f"required: an object of {', '.join(self.extra)} (°C)")
        unknown = sorted(set(given) - set(self.extra))
        if unknown:
            raise InputError(f"rule_readings.{unknown[0]}", f"unknown reading; the rule reads {', '.join(self.extra)}")
        out = {}
        for name in self.extra:
            v = given.get(name)
            if isinstance(v, dict):
                if v.get("unit") is not None and not same_unit(str(v["unit"]), "C"):
                    raise InputError(f"rule_readings.{name}", f"unit {v['unit']!r}; the rule reads °C")
                v = v.get("value")
            if isinstance(v, bool) or not isinstance(v, int | float) or not math.isfinite(v):
                raise InputError(f"rule_readings.{name}", "missing or not a finite number")
            out[name] = float(v)
        return out

    def _t_max(self, given) -> float:
        if given is None:
            return self.cfg.max_c  # a first request: the reset starts at its upper end, as in process
        t = given.get("t_max_c") if isinstance(given, dict) else None
        if isinstance(t, bool) or not isinstance(t, int | float) or not self.cfg.min_c <= t <= self.cfg.max_c:
            raise InputError("rule_state", f"must be the last answer's rule_state: {{\"t_max_c\": a number within "
                             f"[{self.cfg.min_c}, {self.cfg.max_c}]}}")  # fmt: skip
        return float(t)
