"""What evaluation during training measures and what "best" means: `--eval-every`, `--target` and the score.

Light on purpose (no torch, no SB3): the run's config (config.py), the sweep's ranking (sweep.py) and the run
registry read these without loading a learner.

The score, one number, higher is better, used for the best checkpoint, a sweep's ranking and Ray Tune's
schedulers alike:
- with a target: a policy that meets it scores 1000 - its energy change against the built-in controller (%),
  so among those that meet it the lowest energy wins; one that misses scores -1000 - its shortfall (the sum
  over the target's terms of how far each misses, in that term's own units), so the closest to it ranks first;
- without a target: the mean reward per step.
All of these are means over the evaluation weathers (their per-weather rows are in evaluations.csv too).
"""

from __future__ import annotations

import math
import operator
import re
from dataclasses import dataclass, field

HELD_OUT = ("IL", "VA")  # for `evaluate` alone: never tuned on, so never chosen on
OPS = {">=": operator.ge, "<=": operator.le, ">": operator.gt, "<": operator.lt}
MET_SCORE = 1000.0
ENERGY = "energy_change_pct"
REWARD = "reward_mean"


@dataclass
class EvalSettings:
    """`train --eval-every STEPS --eval-weathers W,... --eval-days N --target ...` (saved in config.json)."""

    every: int = 0  # env steps between evaluations of the frozen policy; 0: none
    weathers: list[str] = field(default_factory=list)  # none: the training weathers
    days: int | None = None  # episode length; None: the run's own
    target: str | None = None  # e.g. "in_band_pct>=99.6,energy_change_pct<=-22"
    # the periods each weather is evaluated on: "start" (`days` from January 1) and BOPTEST's two-week scenarios
    # (peak_heat, typical_heat, peak_cool, typical_cool, evaluation/scenarios.py); the figures are their means
    scenarios: list[str] = field(default_factory=lambda: ["start"])

    def check(self, training_weathers: list[str]) -> None:
        if self.every < 0:
            raise ValueError(f"--eval-every takes env steps >= 0 (0: no evaluation), got {self.every}")
        if self.days is not None and not 1 <= self.days <= 365:
            raise ValueError(f"--eval-days must be within 1..365, got {self.days}")
        held = [w for w in self.weathers if w.upper() in HELD_OUT]
        if held:
            raise ValueError(
                f"--eval-weathers {','.join(held)}: {' and '.join(HELD_OUT)} are held out for `parallel-eplus "
                "evaluate`; choosing checkpoints on them would tune on them. Use training or other weathers (default: "
                f"{','.join(training_weathers)})"
            )
        known = ("start", "peak_heat", "typical_heat", "peak_cool", "typical_cool")
        unknown = [s for s in self.scenarios if s not in known]
        if unknown or not self.scenarios:
            raise ValueError(f"--eval-scenarios {','.join(unknown) or '(none)'}: one or more of {', '.join(known)}")
        if self.target is not None:
            parse_target(self.target)
            if not self.every:
                raise ValueError("--target is checked at each evaluation: pass --eval-every STEPS too")


@dataclass(frozen=True)
class Term:
    kpi: str
    op: str
    value: float

    def met(self, kpis: dict) -> bool:
        x = kpis.get(self.kpi, math.nan)
        return x == x and OPS[self.op](x, self.value)

    def shortfall(self, kpis: dict) -> float:
        x = kpis.get(self.kpi, math.nan)
        if x != x:
            return math.inf
        return 0.0 if self.met(kpis) else abs(x - self.value)

    def __str__(self) -> str:
        return f"{self.kpi}{self.op}{self.value:g}"


def parse_target(text: str | None) -> list[Term]:
    """'in_band_pct>=99.6,energy_change_pct<=-22' -> its terms; a clear error on anything else."""
    if not text:
        return []
    terms = []
    for part in (p.strip() for p in text.split(",") if p.strip()):
        m = re.fullmatch(r"([A-Za-z_][A-Za-z0-9_]*)\s*(>=|<=|>|<)\s*([-+0-9.eE]+)", part)
        try:
            terms.append(Term(m.group(1), m.group(2), float(m.group(3))))
        except (AttributeError, ValueError):
            raise ValueError(
                f"--target {text!r}: each term is KPI>=VALUE or KPI<=VALUE, comma-separated, e.g. "
                "in_band_pct>=99.6,energy_change_pct<=-22 (KPIs: an episode summary's, and energy_change_pct)"
            ) from None
    return terms


def meets(kpis: dict, terms: list[Term]) -> bool:
    return bool(terms) and all(t.met(kpis) for t in terms)


def score(kpis: dict, terms: list[Term]) -> float:
    """The module docstring's score: higher is better."""
    if not terms:
        return float(kpis.get(REWARD, math.nan))
    if meets(kpis, terms):
        return MET_SCORE - float(kpis.get(ENERGY, 0.0))
    return -MET_SCORE - min(sum(t.shortfall(kpis) for t in terms), 1e9)
