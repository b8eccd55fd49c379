"""`--budget-minutes` split across the stages of one building, over every session (a rerun continues with what is
left): scoring is not cut (a half-scored candidate cannot be compared), so training gets what is left after the
scoring done so far and a reserve for what must follow it (scoring the learned controller, exporting it, the report).

The reserve starts as an estimate from the own controls' scoring time on this machine, measured in the same run: a
planner plans every control step (a search over a learned model), which made its evaluations five to nine times slower
than the own controls' on the small and the medium office on this (busy) 2-core machine; a network is about as fast as
the own controls. Once the planner acts in training its own pace replaces the guess (`TrainingDeadline`): the steps
its scoring runs over its steps per second in training, which scoring beats by PLANNER_PACE_RATIO (no refits)."""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Callable
from dataclasses import dataclass

from parallel_eplus.optimize.folders import BuildingFolder

log = logging.getLogger(__name__)

PLANNER_EVAL_FACTOR = 5.0
NETWORK_EVAL_FACTOR = 1.5
EXPORT_RESERVE_S = 60.0  # plus half the own controls' scoring: a planner's export records the own controls
REPORT_RESERVE_S = 30.0
MIN_TRAIN_S = 60.0  # `--quick`'s training: the least it is given
# A preset's new run records the building's own controls (a year on each training weather, with --random-start) and
# fits its model before its first checkpoint: with less than this left, training is not started (a rerun with a larger
# budget starts it) rather than stopped before it has anything to keep; it suggests a budget with SUGGESTED_TRAIN_S
# for training (the first try of the planner preset: 26 minutes of training on 2 cores)
MIN_USEFUL_TRAIN_S = 300.0
SUGGESTED_TRAIN_S = 1500.0
# Scoring a planner's steps against training them (no refits, no exploration): on the medium office with 2 workers,
# trained at 4.0 steps/s (steps 3,000-9,300), then 11,520 steps scored over 20 four-day periods at 6.5 steps/s; 1.5
# keeps a margin
PLANNER_PACE_RATIO = 1.5
PACE_MIN_STEPS, PACE_MIN_S = 100, 60.0  # what the pace is measured over before it is trusted


@dataclass
class TrainingDeadline:
    """When training is stopped (as time.time()), asked again at every poll: the budget's end less the time to score
    and export what it learned, never before `earliest`. `steps` (the run's steps so far), `acting_from` (the step
    from which the planner acts) and `eval_steps` (the control steps its scoring runs): the reserve from the planner's
    own pace once it has been measured; without them, or before, `reserve_s`."""

    end: float
    reserve_s: float
    earliest: float
    steps: Callable[[], int] | None = None
    acting_from: int = 0
    eval_steps: int = 0
    _first: tuple[int, float] | None = None
    _told: bool = False

    def pace(self) -> float | None:
        """Steps per second of the run since the planner acts (this session), once measured."""
        if self.steps is None or not self.eval_steps:
            return None
        try:
            steps, now = self.steps(), time.time()
        except (OSError, ValueError):
            return None
        if steps < self.acting_from or steps == 0:
            return None
        if self._first is None:
            self._first = (steps, now)
            return None
        done, spent = steps - self._first[0], now - self._first[1]
        return done / spent if done >= PACE_MIN_STEPS and spent >= PACE_MIN_S else None

    def __call__(self) -> float:
        reserve, rate = self.reserve_s, self.pace()
        if rate:
            reserve = self.eval_steps / (PLANNER_PACE_RATIO * rate) + EXPORT_RESERVE_S + REPORT_RESERVE_S
            if not self._told:
                self._told = True
                log.info("the planner trains at %.1f steps/s: scoring it (%d steps) should take %.0f min; training "
                         "stops at %s", rate, self.eval_steps, (reserve - EXPORT_RESERVE_S - REPORT_RESERVE_S) / 60,
                         time.strftime("%H:%M", time.localtime(max(self.earliest, self.end - reserve))))  # fmt: skip
        return max(self.earliest, self.end - reserve)


class Budget:
    """The building's budget: what earlier sessions spent (status.json's spent_s) plus this session's time."""

    def __init__(self, folder: BuildingFolder, minutes: float):
        self.folder, self.total_s = folder, 60.0 * minutes
        status = folder.status()
        self.before_s = float(status.get("spent_s", 0.0))
        status["sessions"] = int(status.get("sessions", 0)) + 1
        folder.write_status(status)
        self.t0 = time.time()

    def spent_s(self) -> float:
        return self.before_s + time.time() - self.t0

    def left_s(self) -> float:
        return self.total_s - self.spent_s()

    def save(self) -> None:
        """This session's time into status.json (after each stage, and when the session ends however it ends)."""
        status = self.folder.status()
        status["spent_s"] = round(self.spent_s(), 1)
        self.folder.write_status(status)

    def reserve_after_training(self, own_scoring_s: float, planner: bool) -> float:
        factor = PLANNER_EVAL_FACTOR if planner else NETWORK_EVAL_FACTOR
        return factor * own_scoring_s + EXPORT_RESERVE_S + 0.5 * own_scoring_s + REPORT_RESERVE_S

    def too_short(self, reserve_s: float, floor_s: float) -> str | None:
        """Why training is not started (too little of the budget left for it), or None."""
        share = self.left_s() - reserve_s
        if share >= floor_s:
            return None
        need = math.ceil((self.spent_s() + reserve_s + SUGGESTED_TRAIN_S) / 60)
        return (f"the budget leaves {max(0.0, share) / 60:.1f} min for training after scoring ({reserve_s / 60:.1f} "
                "min reserved to score and export it): too little for the preset's first checkpoint (it records the "
                f"own controls and fits its model first); rerun with --budget-minutes {need} to train it")  # fmt: skip

    def training_deadline(self, reserve_s: float, **pace) -> tuple[TrainingDeadline, float]:
        """(the deadline, the seconds it gives for now): what is left after the reserve, at least MIN_TRAIN_S; `pace`:
        TrainingDeadline's steps, acting_from and eval_steps, to follow a planner's own pace."""
        now = time.time()
        share = max(MIN_TRAIN_S, self.left_s() - reserve_s)
        return TrainingDeadline(now + self.left_s(), reserve_s, now + MIN_TRAIN_S, **pace), share
