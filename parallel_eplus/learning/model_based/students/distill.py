"""The planner into the usual policy network: imitation on its own actions (training/imitation.py's fit).

The planner needs the model, the weather file's future and a few milliseconds per step; a policy network needs
none of them, and is what `evaluate`, `train --init-from` (fine-tuning with `--comfort-target`, the Lagrangian
learner) and deployment take. The fit is `imitation.clone` on the observations the planner acted on and the
actions it chose (before any exploration noise), without the re-drawn temperatures `--init-from-baseline` uses:
the planner acts on the zone temperatures (it is feedback), so the policy must too.
"""

from __future__ import annotations

import json
import logging
import math
from dataclasses import replace
from pathlib import Path

import numpy as np
from stable_baselines3.common.vec_env import VecNormalize

from parallel_eplus import io
from parallel_eplus.buildings.building import load_building
from parallel_eplus.buildings.scaling import denormalize
from parallel_eplus.learning.imitation import Demonstrations, clone
from parallel_eplus.runs.checkpoints import save_checkpoint
from parallel_eplus.runs.run_files import MODEL_FILE

log = logging.getLogger(__name__)
MIN_UPDATES = 3000  # gradient steps for a large record (a half-year of the planner's steps)
MAX_EPOCHS = 50  # passes over a small record: the fit's cost in proportion to the data, not 3,000 steps on 300 rows


def demonstrations(building: str | None, observations: np.ndarray, actions: np.ndarray) -> Demonstrations:
    b = load_building(building)
    low = np.array([a.low for a in b.actions])
    high = np.array([a.high for a in b.actions])
    physical = denormalize(np.clip(actions, -1, 1), low, high)
    return Demonstrations(observations, actions, physical, low, high, tuple(a.name for a in b.actions))


def fit(model, env: VecNormalize, cfg, observations: np.ndarray, actions: np.ndarray) -> dict:
    """Fit `model`'s policy to the planner's actions (`cfg`: the run's TrainConfig); returns the fit's report."""
    demos = demonstrations(cfg.building, observations, actions)
    # `MIN_UPDATES` gradient steps where the record is large (the imitation settings' epochs are sized for a year of
    # records), at most `MAX_EPOCHS` passes where it is small: a 2k-step run's refits took minutes on a few hundred rows
    wanted = math.ceil(MIN_UPDATES * cfg.imitation.batch_size / max(len(demos), 1))
    epochs = max(cfg.imitation.epochs, min(wanted, MAX_EPOCHS))
    report = clone(model, env, demos, replace(cfg.imitation, epochs=epochs), cfg.seed)
    spread = demos.physical.std(axis=0)  # a constant (the mean action) scores this
    report["rmse_of_mean_action"] = dict(zip(demos.names, spread.round(4).tolist(), strict=True))
    return report


def act(model, env: VecNormalize, observations: np.ndarray) -> np.ndarray:
    """The fitted policy's deterministic actions on raw observations."""
    action, _ = model.policy.predict(env.normalize_obs(observations), deterministic=True)
    return np.clip(action, -1, 1).astype(np.float32)


def distill(model, env: VecNormalize, cfg, observations: np.ndarray, actions: np.ndarray) -> Path:
    """Fit `model`'s policy (a new one, the run's network: TRPO's by default) to the planner's actions; save it as
    the run's model.zip (`cfg`: the run's TrainConfig), its fit report as distill.json."""
    report = fit(model, env, cfg, observations, actions)
    io.write_text(cfg.run_dir / "distill.json", json.dumps(report, indent=2))
    rmse = ", ".join(f"{k} {v:.3g}" for k, v in report["rmse"].items())
    log.info("distilled the planner from %d steps (RMSE, physical units: %s)", report["samples"], rmse)
    return save_checkpoint(model, env, cfg.run_dir / MODEL_FILE)
