"""`evaluate --oracle`'s settings: how far it looks, how often it decides, what it searches and what a plan costs."""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

from parallel_eplus.learning.settings import FromText, setting


@dataclass
class OracleSettings(FromText):
    """The oracle's settings (`evaluate --oracle NAME=VALUE,...`; `--oracle help` lists them)."""

    flag: ClassVar[str] = "--oracle"
    SECTIONS: ClassVar[dict[str, str]] = {
        "horizon_h": "The search (learning/oracle/search.py): decisions, horizon, candidates",
        "comfort_weight": "What a plan costs (the learned planner's cost, runtime/planner.py)",
    }

    horizon_h: float = setting(24.0, "hours each candidate is played ahead in a fork of the running simulation")
    interval_min: int = setting(60, "minutes between decisions; a candidate holds one target per interval")
    candidates: int = setting(
        24,
        "candidate sequences played per decision (the warm start, the last action, the rule's, then coordinate moves)",
    )
    step: float = setting(
        0.2,
        "the first move of the targets (normalized units: 3 K of the data "
        "center's supply setpoint); halved after a round that finds nothing better",
    )
    offsets: bool = setting(
        False,
        "spend the budget left after the closed-loop candidates on offsets added to the "
        "first rule's actions (the building's rule, else its own schedules), each played in "
        "closed loop: a residual on the rule",
    )
    warmup_candidates: int = setting(
        4,
        "candidates per decision in a test period's warm-up before its last day "
        "(its days are not scored: enough to enter the period in a sensible state)",
    )
    parallel: int = setting(2, "forks played at once (the cores to use)")
    seed: int = setting(0, "the sampler's seed (each decision's own from it and the decision's time)")
    max_increment: float = setting(
        0.15,
        "largest change of each action per control step (normalized units), as "
        "the learned planner's: a jump to a new target is made up over the next steps",
    )
    comfort_weight: float = setting(
        10.0,
        "the comfort term's weight (the learned planner's Lagrange multiplier's "
        "place; the energy term is about 1 a step)",
    )
    margin: float = setting(
        0.25,
        "K inside each zone's bounds (widened by the spec's tolerance, as `evaluate` "
        "counts in band) where the comfort term starts: the learned planner's --comfort-margin",
    )
    terminal_weight: float = setting(0.0, "the horizon's last step's comfort term counts 1 + this many times")

    def __post_init__(self):
        super().__post_init__()
        if self.horizon_h <= 0 or self.interval_min <= 0:
            raise ValueError(f"horizon_h {self.horizon_h} and interval_min {self.interval_min}: both > 0")
        if self.horizon_h * 60 < self.interval_min:
            raise ValueError(f"horizon_h {self.horizon_h}: at least one interval ({self.interval_min} min)")
        if self.candidates < 1 or self.step <= 0 or self.parallel < 1 or self.warmup_candidates < 1:
            raise ValueError("candidates, parallel and warmup_candidates: at least 1; step > 0")
        if self.margin <= 0:
            raise ValueError(f"margin {self.margin}: K, > 0")
