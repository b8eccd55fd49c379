"""`train --algorithm mbpo`'s ensemble beside SAC: where it starts from (a resumed run, a planner run, or the
building's own controls recorded first). The rollouts themselves are learning/model_based/mbpo/algorithm.py."""

from __future__ import annotations

import logging
from pathlib import Path

import numpy as np

from parallel_eplus.learning.model_based.control.mpc import MPC
from parallel_eplus.learning.model_based.mbpo import algorithm as mbpo
from parallel_eplus.learning.model_based.mbpo import state as mbpo_state
from parallel_eplus.learning.model_based.model.dataset import Transitions
from parallel_eplus.learning.model_based.students.through_model import Starts
from parallel_eplus.training.config import TrainConfig

log = logging.getLogger(__name__)


def model_rollouts(cfg: TrainConfig, venv, checkpoint: Path | None, progress: bool):
    """`--algorithm mbpo`'s ensemble beside SAC (mbpo/algorithm.py): a resumed run's own, a planner run's
    (`--init-from`), or fitted on the building's own controls recorded first."""
    state_dir = cfg.run_dir / mbpo_state.STATE_DIR
    n = venv.num_envs
    if checkpoint is not None and (state_dir / mbpo_state.STARTS).is_file():
        mpc, data, starts = mbpo_state.load_state(state_dir, n, cfg.seed)
        log.info("the ensemble resumes from %s: %d transitions, %d start states", state_dir, len(data), len(starts))
    elif cfg.init_from is not None:
        mpc, data, starts = mbpo_state.from_planner_run(Path(cfg.init_from), n, cfg.seed)
        width = venv.observation_space.shape[0]
        if mpc.building != cfg.building:
            raise ValueError(f"--init-from {cfg.init_from}: a planner of building {mpc.building!r}; this run's is "
                             f"{cfg.building!r} (give it --building {mpc.building})")  # fmt: skip
        if starts.obs and len(starts.obs[0]) != width:
            raise ValueError(
                f"--init-from {cfg.init_from}: its planner's states hold {len(starts.obs[0])} values, "
                f"this run observes {width}: give the planner run's --time-features and "
                "--schedule-features, or a planner folder alone (planner/) to start without its states"
            )
        log.info("%s starts from the model and data of %s: %d transitions, %d start states", cfg.run_name,
                 cfg.init_from, len(data), len(starts))  # fmt: skip
    else:
        mpc = MPC(cfg.building, cfg.mpc, cfg.comfort.margin_c, cfg.reward.power_weight, n, cfg.seed,
                  objective=cfg.objective)  # fmt: skip
        data, starts = Transitions(mpc.layout), Starts()
    if checkpoint is None and not len(starts):  # nothing to branch from yet: the building's own controls first
        mbpo_state.record_own_controls(cfg, mpc, data, starts, progress)
        log.info("recorded the building's own controls: %d transitions, %d start states", len(data), len(starts))
    if cfg.init_from is None and checkpoint is None:
        mpc.model.fit(data, np.arange(len(data)), cfg.mpc.epochs)
        mpc.set_support(data.array("a"))
        log.info("model fitted on the building's own controls: %d transitions", len(data))
    return mbpo.ModelRollouts(cfg, mpc, data, starts, state_dir)
