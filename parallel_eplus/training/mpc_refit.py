"""The planner's model refitted on everything a run has seen, and what TensorBoard and model_error.json show of it.

A day of the data is held out in blocks (a quarter day when there is too little for one), so the logged errors are
the model's on days it did not fit, beside persistence's.
"""

from __future__ import annotations

import json
import logging
import time
from pathlib import Path

import numpy as np

from parallel_eplus import io
from parallel_eplus.learning.model_based.model.dynamics import summary

log = logging.getLogger(__name__)


def refit(mpc, data, building, horizon: int, epochs: int, logger, run_dir: Path) -> None:
    """Fit `mpc`'s ensemble on `data` for `epochs`, refresh the planner, log the held-out errors and support."""
    t0 = time.perf_counter()
    block = building.steps_per_day
    held = data.held_out(block)
    if held.all() or not held.any():  # too little data for a held-out day: quarter days
        block = max(block // 4, 1)
        held = data.held_out(block)
    loss = mpc.model.fit(data, np.flatnonzero(~held), epochs)
    mpc.refresh()
    mpc.set_support(data.array("a"))
    errors = mpc.model.errors(data, held, horizon)
    for key, value in errors.items():
        logger.record(f"model/{key}", value)
    logger.record("model/train_loss", loss)
    logger.record("model/rows", len(data))
    logger.record("model/fit_s", time.perf_counter() - t0)
    logger.record("planner/comfort_weight", mpc.comfort_weight)
    for i, name in enumerate(a.name for a in building.actions):
        logger.record(f"planner/support/{name}_low", float(mpc.support[0][i]))
        logger.record(f"planner/support/{name}_high", float(mpc.support[1][i]))
    io.write_text(run_dir / "model_error.json", json.dumps(errors, indent=2))
    log.info("model fitted on %d rows (%.1f s); held-out %s", int((~held).sum()), time.perf_counter() - t0,
             summary(errors, mpc.layout.state_names, horizon))  # fmt: skip
