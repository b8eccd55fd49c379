"""What one `optimize` is asked to do, in one place: the weathers, the test periods, the objective, the budget, and what
`--quick` changes (so the report can say exactly how a short run differs from a real one)."""

from __future__ import annotations

import os
from dataclasses import asdict, dataclass, field

SCENARIOS = ("peak_heat", "typical_heat", "peak_cool", "typical_cool")  # BOPTEST's four test periods
QUICK = "quick"  # `--quick`'s one fixed period, standing in for the four

# `--quick`: a smoke run of every stage (the suite's test, a first look at a new model), not a result. One fixed winter
# window instead of BOPTEST's four periods (no year of the own controls to find the days in), 2 scored days after one
# day's warm-up, 2-day training episodes, and a short planner training: the own controls recorded for 2 days, a
# 288-step exploration, refits every 288 steps, a search of 64 candidates over 2 iterations (the preset's: 256 over 3),
# and a network trained through the model (the data center's preset) in 100 gradient steps a refit (its: 1,500).
QUICK_DAY = 10  # January 11 (0: January 1), scored with the 12th; the 10th is the warm-up
QUICK_SCORED_DAYS = 2
QUICK_WARMUP_DAYS = 1
QUICK_RUN_DAYS = 2
QUICK_TIMESTEPS = 600
QUICK_MPC = {"record_days": 2, "explore_steps": 288, "refit_every": 288, "candidates": 64, "iterations": 2}
QUICK_STUDENT = {"student_updates": 100}  # where the preset trains a network through the model (`student`)
QUICK_CHECKPOINT_EVERY = 144


@dataclass(frozen=True)
class OptimizeSettings:
    """The options of one `optimize` (cli/optimize.py fills it)."""

    weathers: tuple[str, ...] = ("CA", "CO", "FL")  # training weathers: every choice but the last is made on them
    held_out: tuple[str, ...] = ("IL", "VA")  # never trained on, never used for a choice but the final one
    scenarios: tuple[str, ...] = SCENARIOS
    scenario_days: int = 14  # scored days per test period (BOPTEST's: 14), centred on its day
    quick: bool = False
    objective: str = "hvac"  # what the choice (and the training) minimises: "hvac" (HVAC energy) or "cost" (the bill)
    preset: str | None = None  # None: the building's (candidates.py)
    timesteps: int | None = None  # None: the preset's (QUICK_TIMESTEPS with --quick)
    run_days: int | None = None  # training episodes; None: the preset's (QUICK_RUN_DAYS with --quick)
    workers: int = field(default_factory=lambda: os.cpu_count() or 1)
    budget_minutes: float = 45.0  # over every session of a building (a rerun continues with what is left)

    def __post_init__(self):
        if self.objective not in ("hvac", "cost"):
            raise ValueError(f"--objective: hvac or cost, not {self.objective!r}")
        if set(self.weathers) & set(self.held_out):
            raise ValueError(f"--held-out {','.join(self.held_out)} overlaps --weathers {','.join(self.weathers)}: "
                             "a held-out weather is one nothing was chosen or trained on")  # fmt: skip
        if not self.weathers or not self.held_out:
            raise ValueError("optimize needs training weathers (--weathers) and held-out ones (--held-out)")
        if not 1 <= self.scenario_days <= 14:
            raise ValueError("--scenario-days: 1 to 14 (BOPTEST's periods are 14 days)")
        if self.workers < 1 or self.budget_minutes <= 0:
            raise ValueError("--workers must be at least 1 and --budget-minutes above 0")
        unknown = set(self.scenarios) - set(SCENARIOS) - {QUICK}
        if unknown:
            raise ValueError(f"--scenarios: unknown {sorted(unknown)}; the four are {', '.join(SCENARIOS)}")

    @property
    def periods(self) -> tuple[str, ...]:
        """The test periods scored: BOPTEST's asked for, or `--quick`'s one."""
        return (QUICK,) if self.quick else self.scenarios

    @property
    def all_weathers(self) -> tuple[str, ...]:
        return (*self.weathers, *self.held_out)

    def metric(self, kind: str) -> str:
        """The results column the choice minimises: the bill with --objective cost; else HVAC energy, or a data
        center's facility energy (its servers draw more with warmer inlet air: HVAC alone would reward that)."""
        if self.objective == "cost":
            return "bill"
        return "energy_kwh" if kind == "datacenter" else "hvac_energy_kwh"

    def fingerprint(self) -> dict:
        """The settings the folder's results depend on: a rerun with other values would mix two questions' answers.
        The budget, the workers and the training's length are not in it: a rerun may give more of each."""
        d = asdict(self)
        for key in ("workers", "budget_minutes", "timesteps"):
            d.pop(key)
        return {k: list(v) if isinstance(v, tuple) else v for k, v in d.items()}
