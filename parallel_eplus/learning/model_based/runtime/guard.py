"""The realised test for leaving the own plan (`--mpc guard_k`): what a move off it cost, measured, not predicted.

With `comfort_reference = "baseline"` the planner leaves the building's own plan where its model predicts a saving, and
on the DOE prototypes those moves were the model's noise: exact on the baseline (`baseline_radius=0`), off it the zones
lost comfort the model did not see (docs/model-based.md). A higher threshold on the predicted saving did not make it
safe, because the model's error is not in its prediction of the saving. The guard reads the building instead: at each
step's end, the zones' discomfort beyond their bounds (K, summed, where the band applies) against what the model
predicted for the own plan's step from the same state. A worker whose planner left the own plan within the last
`steps` steps and whose zones now exceed that by more than `k` plays the own plan for the next `steps` steps.

A false alarm costs only savings (the own plan is what the building would have done); a move that costs comfort
costs at most one step's worth before the own plan is back. The state is three numbers a worker, so the served
planner carries it in the request and the answer (planner_runtime.py), as it carries the plan's warm start.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from parallel_eplus.learning.model_based.runtime.planner import Plan

LEFT = 1e-3  # normalized units: an action this far from the own plan's has left it


def discomfort(temps: np.ndarray, bounds: np.ndarray, applies: np.ndarray, tolerance: float) -> np.ndarray:
    """[W]: each worker's K beyond its zones' bounds, summed over zones, where the band applies; temps [W, K],
    bounds [W, K, 2] as the calendar gives them (widened by the spec's `tolerance`, which is taken off again:
    occupied discomfort, the score, counts from the thermostat's setpoint, comfort.py)."""
    over = np.maximum(np.maximum(bounds[..., 0] + tolerance - temps, temps - bounds[..., 1] + tolerance), 0.0)
    return over.sum(-1) * (np.asarray(applies) > 0)


@dataclass
class GuardState:
    """One worker's guard: steps it still plays the own plan, steps since its planner last left the own plan,
    and the discomfort (K) the model predicted for the own plan's step now under way (None: nothing to compare)."""

    hold: int = 0
    since_left: int = 1_000_000
    expected_k: float | None = None

    @classmethod
    def of(cls, value) -> GuardState:
        """From a served request's `guard` (None: a fresh one); refuses what is not one."""
        if value is None:
            return cls()
        if not isinstance(value, dict) or set(value) - {"hold", "since_left", "expected_k"}:
            raise ValueError("must be the last answer's guard: {hold, since_left, expected_k}")
        hold, since, expected = value.get("hold", 0), value.get("since_left", 1_000_000), value.get("expected_k")
        if not all(isinstance(v, int) and not isinstance(v, bool) and v >= 0 for v in (hold, since)):
            raise ValueError("hold and since_left must be whole numbers >= 0")
        if expected is not None and (isinstance(expected, bool) or not isinstance(expected, int | float)
                                     or not np.isfinite(expected) or expected < 0):  # fmt: skip
            raise ValueError("expected_k must be a number >= 0 or null")
        return cls(hold, since, None if expected is None else float(expected))

    def as_dict(self) -> dict:
        return {"hold": self.hold, "since_left": self.since_left,
                "expected_k": None if self.expected_k is None else round(self.expected_k, 6)}  # fmt: skip


class Guard:
    """Every worker's `GuardState`: `check` before a plan (which workers play the own plan), `record` after it.
    `tolerance`: the spec's, by which the calendar's bounds are widened (`discomfort` takes it off)."""

    def __init__(self, workers: int, k: float, steps: int, tolerance: float):
        self.k, self.steps, self.tolerance = k, steps, tolerance
        self.states = [GuardState() for _ in range(workers)]
        self.trips = 0

    def reset(self, worker: int) -> None:
        self.states[worker] = GuardState()

    def check(self, temps: np.ndarray, bounds: np.ndarray, applies: np.ndarray) -> np.ndarray:
        """[W] bool: the workers that play the own plan this step, from the zone temperatures [W, K] observed at the
        end of the step just taken, and the bounds [W, K, 2] and whether the band applies [W] then."""
        realised = discomfort(temps, bounds, applies, self.tolerance)
        hold = np.zeros(len(realised), bool)
        for i, g in enumerate(self.states[: len(realised)]):
            if g.expected_k is not None and g.since_left <= self.steps and realised[i] - g.expected_k > self.k:
                g.hold = self.steps
                self.trips += 1
            hold[i] = g.hold > 0
        return hold

    def record(self, plan: Plan, bounds: np.ndarray, applies: np.ndarray) -> None:
        """After the plan: whether each worker left the own plan, and the discomfort the model predicts for the own
        plan's step (`plan.own_next`) against the bounds [W, K, 2] and whether the band applies [W] at its end."""
        expected = discomfort(plan.own_next, bounds, applies, self.tolerance)
        for i, g in enumerate(self.states[: len(plan.action)]):
            g.hold = max(g.hold - 1, 0)
            g.since_left = 0 if np.any(np.abs(plan.action[i] - plan.own_action[i]) > LEFT) else g.since_left + 1
            g.expected_k = float(expected[i])
