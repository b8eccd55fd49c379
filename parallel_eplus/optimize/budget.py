"""`--budget-minutes` split across the stages of one building, over every session (a rerun continues with what is
left): scoring is not cut (a half-scored candidate cannot be compared), so training gets what is left after the
scoring done so far and a reserve for what must follow it (scoring the learned controller, exporting it, the report).

The reserve is estimated from the own controls' scoring time on this machine, measured in the same run: a planner
plans every control step (a search over a learned model), which made its evaluations about five times slower than
the own controls' on the small office on this 2-core machine; a network is about as fast as the own controls."""

from __future__ import annotations

import math
import time

from parallel_eplus.optimize.folders import BuildingFolder

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

    def training_deadline(self, reserve_s: float) -> tuple[float, float]:
        """(deadline as time.time(), the seconds it gives): what is left after the reserve, at least MIN_TRAIN_S."""
        share = max(MIN_TRAIN_S, self.left_s() - reserve_s)
        return time.time() + share, share
