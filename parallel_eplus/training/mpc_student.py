"""The policy network a planner run leaves: fitted to the planner's steps, or trained on its cost through the model.

During DAgger's phase (`--mpc dagger_share`) the student acts and the planner labels its states; at the end of the
run it is fitted once more (distill.py) or, with `--mpc student=gradient`, trained through the model
(through_model.py) from the states of the planner's steps. Those steps are what a checkpoint keeps of it.
"""

from __future__ import annotations

import json
import logging
from pathlib import Path

import numpy as np

from parallel_eplus import io
from parallel_eplus.learning.model_based.students.distill import act, distill, fit
from parallel_eplus.learning.model_based.students.through_model import Starts, train_student
from parallel_eplus.runs.checkpoints import save_checkpoint
from parallel_eplus.runs.run_files import MODEL_FILE
from parallel_eplus.training.config import TrainConfig

log = logging.getLogger(__name__)


class Student:
    """The planner's steps so far and the network learned from them (made on first use)."""

    def __init__(self, cfg: TrainConfig, venv, building, new_model, logger):
        self.cfg, self.venv, self.building, self.new_model, self.logger = cfg, venv, building, new_model, logger
        self.gradient = cfg.mpc.student == "gradient"
        self.obs, self.act, self.prev, self.times, self.weathers = [], [], [], [], []  # per vector step
        self.net = None  # (model, VecNormalize)
        self.fitted = False  # DAgger's phase: it acts

    @property
    def rows(self) -> int:
        return sum(map(len, self.obs))

    def add(self, obs: np.ndarray, planned: np.ndarray, prev: np.ndarray, infos) -> None:
        """One vector step the planner planned: its states, actions, the actions before them, when and where."""
        self.obs.append(obs.copy())
        self.act.append(planned)
        self.prev.append(prev.copy())
        self.times.append(np.array([info["time"] for info in infos], object))
        self.weathers.append(np.array([str(info["weather"]) for info in infos]))

    def network(self):
        """The policy the planner is distilled into, with its observation normalizer."""
        if self.net is None:
            from stable_baselines3.common.vec_env import VecNormalize

            env = VecNormalize(self.venv, norm_obs=True, norm_reward=False, gamma=self.cfg.trpo.gamma)
            self.net = (self.new_model(self.cfg, env), env)
        return self.net

    def actions(self, obs: np.ndarray) -> np.ndarray:
        return act(*self.network(), obs)

    def refit(self, mpc, seed: int) -> None:
        """Fit it to the planner's steps (once with student=gradient: the clone it starts from; then through the
        model)."""
        model, env = self.network()
        if self.gradient and self.fitted:
            for name, value in self._through_model(mpc, seed)["cost"].items():
                self.logger.record(f"distill/through_model/{name}", value)
            return
        report = fit(model, env, self.cfg, np.concatenate(self.obs), np.concatenate(self.act))
        for name, value in report["rmse"].items():
            self.logger.record(f"distill/rmse/{name}", value)
        self.fitted = True

    def finish(self, mpc, steps: int) -> Path:
        """The run's end: the distilled (or through-model) policy saved as runs/<name>/model.zip."""
        model, env = self.network()
        model.num_timesteps = steps  # what the run took (a sweep reads it from model.zip)
        if not self.gradient:
            return distill(model, env, self.cfg, np.concatenate(self.obs), np.concatenate(self.act))
        if not self.fitted:
            self.refit(mpc, self.cfg.seed + steps)  # the clone it starts from
        report = self._through_model(mpc, self.cfg.seed + steps)
        io.write_text(self.cfg.run_dir / "distill.json", json.dumps(report, indent=2))
        log.info("trained the student through the model from %d states: %s", report["starts"], report["cost"])
        return save_checkpoint(model, env, self.cfg.run_dir / MODEL_FILE)

    def _through_model(self, mpc, seed: int) -> dict:
        """Trained on the planner's cost through the model, from the states of the planner's steps (the student's
        own in DAgger's phase)."""
        prev, obs = np.concatenate(self.prev), np.concatenate(self.obs)
        # the rows with starts (older checkpoints: the newest)
        starts = Starts.of(obs[len(obs) - len(prev) :], prev, np.concatenate(self.times), np.concatenate(self.weathers))
        model, env = self.network()
        return train_student(mpc, self.building, model, env, starts, self.cfg, seed)

    # -- checkpoints ----------------------------------------------------------------------------
    def arrays(self) -> tuple | None:
        """What a checkpoint keeps: (obs, act) and, where there are any, (prev, times, weathers)."""
        if not self.obs:
            return None
        arrays = (np.concatenate(self.obs), np.concatenate(self.act))
        if self.prev:  # where each planner step started from (a checkpoint before them has none)
            times = np.concatenate(self.times).astype("datetime64[s]")
            arrays += (np.concatenate(self.prev), times, np.concatenate(self.weathers))
        return arrays

    def restore(self, arrays: tuple | None) -> None:
        if arrays is None:
            return
        self.obs, self.act = [arrays[0]], [arrays[1]]
        if len(arrays) == 5:  # the starts of a student trained through the model (older checkpoints lack them)
            self.prev, self.weathers = [arrays[2]], [arrays[4]]
            self.times = [arrays[3].astype("datetime64[s]").astype(object)]
