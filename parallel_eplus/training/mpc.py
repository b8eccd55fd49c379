"""`train --algorithm mpc`: learn the building from the workers' own data, plan on it, distil the planner.

The model, the planner and their data live in learning/model_based/; this module runs them as a training run.

The Dyna loop (Sutton 1991) over the service's workers and vector env (local or Ray):
1. record the building's own controls on the training weathers (sources.py) and fit the ensemble;
2. explore around them for `explore_steps` env steps, then let the planner act (control.py: one batched plan for
   every worker per vector step), refitting the model every `refit_every` steps on everything seen so far;
3. at the end, distil the planner into the usual policy network: runs/<name>/model.zip, fitted to the planner's
   actions (distill.py) or, with `--mpc student=gradient`, trained on the planner's cost through the model
   (through_model.py).

The comfort weight of the planner is the run's Lagrange multiplier (`--comfort-target`, learning/lagrangian.py),
updated at every refit from the share of zone samples in band the planner achieved since the last one. What a run
leaves, and what TensorBoard shows: docs/model-based.md.
"""

from __future__ import annotations

import logging
import shutil
import time
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import torch as th
from stable_baselines3.common.callbacks import BaseCallback
from tqdm import tqdm

from parallel_eplus import io
from parallel_eplus.buildings.building import load_building
from parallel_eplus.buildings.weather.files import weather_label
from parallel_eplus.errors import EnergyPlusError, Interrupts
from parallel_eplus.learning.lagrangian import Lagrangian
from parallel_eplus.learning.model_based.control.checkpoint import Checkpoint, newest_checkpoint
from parallel_eplus.learning.model_based.control.mpc import MPC, PLANNER_FILE
from parallel_eplus.learning.model_based.control.saved_planner import planner_controller
from parallel_eplus.learning.model_based.model.dataset import ORIGINS, Transitions
from parallel_eplus.learning.model_based.model.own_level import BatchComfort, OwnLevel
from parallel_eplus.learning.model_based.model.sources import Explorer, record_own_controls
from parallel_eplus.runs.run_files import BEST_DIR
from parallel_eplus.runs.run_status import RunStatus
from parallel_eplus.training.callbacks import CallbackHost, EpisodeMetrics, tensorboard_logger
from parallel_eplus.training.config import TrainConfig
from parallel_eplus.training.mpc_refit import refit
from parallel_eplus.training.mpc_student import Student

log = logging.getLogger(__name__)
# The student takes over (DAgger) once it has this many of the planner's steps to learn from: a day of one worker.
# (A short run whose exploration ended within DAgger's share fitted a student on one step and let it act.)
DAGGER_MIN_ROWS = 96


def train_mpc(cfg: TrainConfig, checkpoint: Path | None, progress: bool, make_vec_env, new_model,
              callbacks: Sequence[BaseCallback] = (), evaluator=None) -> Path:  # fmt: skip
    """Run (or resume from `checkpoint`) the Dyna loop; returns the distilled policy's model.zip (or the planner's
    file without distillation). Ctrl-C, SIGTERM or a worker's failure saves a checkpoint first.

    `make_vec_env(cfg)`: the workers, as every algorithm gets them; `new_model(cfg, env)`: the policy to distil
    into (train.py's, passed in so the two modules do not import each other). `callbacks` see every vector step, and
    each refit as the end of a batch (a sweep's trial reports then: experiments/tune_trial.py). `evaluator`
    (`--eval-every`, training/periodic_eval.py): the planner as it stands, frozen, on the validation weathers every
    `every` steps, its best kept as best/planner/."""
    th.set_num_threads(1)
    with RunStatus(cfg.run_dir, cfg.timesteps) as status:
        venv = make_vec_env(cfg)
        try:
            return _Loop(cfg, venv, status, progress, new_model, callbacks, evaluator).run(checkpoint)
        finally:
            venv.close()


class _Loop:
    def __init__(self, cfg: TrainConfig, venv, status: RunStatus, progress: bool, new_model, callbacks=(),
                 evaluator=None):  # fmt: skip
        self.evaluator, self._t0 = evaluator, time.monotonic()
        self.cfg, self.venv, self.s, self.new_model = cfg, venv, cfg.mpc, new_model
        self.building = load_building(cfg.building)
        self.mpc = MPC(
            cfg.building,
            self.s,
            cfg.comfort.margin_c,
            cfg.reward.power_weight,
            venv.num_envs,
            cfg.seed,
            objective=cfg.objective,
        )
        self.data = Transitions(self.mpc.layout)
        self.lagrangian = Lagrangian.start(cfg.comfort) if cfg.constrained and self.s.comfort_weight is None else None
        fixed = self.s.comfort_weight
        self.mpc.comfort_weight = cfg.comfort.multiplier_init if fixed is None else fixed  # 0: comfort unpaid
        self.steps, self.replay, self.own_level = 0, {}, None
        if self.s.student == "gradient" and cfg.forecast_hours:
            raise ValueError(
                "--mpc student=gradient: a policy observing --forecast cannot be rebuilt along the "
                "model's rollouts; leave --forecast out (the clock's features are rebuilt)"
            )
        self.logger = tensorboard_logger(Path(cfg.tensorboard_dir) / str(cfg.run_name))
        self.student = Student(cfg, venv, self.building, new_model, self.logger)
        self.shim = CallbackHost(venv, self.logger)
        self.bar = tqdm(total=cfg.timesteps, unit="step", disable=not progress, desc=f"train {cfg.run_name}")
        self.callbacks = [EpisodeMetrics(cfg.run_dir / "episodes.csv", self.bar, 365 * self.building.steps_per_day),
                          status, *callbacks]  # fmt: skip
        self.checkpoints = Checkpoint(cfg.run_dir / "checkpoints")

    # -- the run --------------------------------------------------------------------------------
    def run(self, checkpoint: Path | None) -> Path:
        if checkpoint is None:
            self._record()
            self._refit(self.s.epochs)
        else:
            self._restore(checkpoint)
        for cb in self.callbacks:
            cb.init_callback(self.shim)
        self.shim.num_timesteps = self.steps
        self.bar.update(self.steps)
        try:
            with Interrupts():
                self._steps()
        except BaseException as e:  # Ctrl-C, SIGTERM, a worker's failure, a sweep stopping its trial
            path = self._save_checkpoint()
            cause = (
                "stopped by the failure below" if isinstance(e, EnergyPlusError) else f"stopped ({type(e).__name__})"
            )
            cause = "interrupted" if isinstance(e, KeyboardInterrupt) else cause
            log.warning("%s at step %d; checkpoint saved: %s", cause, self.steps, path)
            log.warning("resume with: parallel-eplus train --resume %s", self.cfg.run_dir)
            raise
        finally:
            self.bar.close()
        self.data.save(self.cfg.run_dir / "transitions.npz")
        planner = self._save_planner() / PLANNER_FILE
        self._save_checkpoint()
        if not self.s.distill or not self.student.rows:
            return planner
        return self.student.finish(self.mpc, self.steps)

    def _steps(self) -> None:
        venv, n = self.venv, self.venv.num_envs
        obs = venv.reset()
        infos = venv.reset_infos
        a_last = np.tile(self.mpc.initial, (n, 1))
        step_of = np.zeros(n, int)
        episode_of = np.arange(n) + 1000 * (1 + self.steps // 1000)  # unique episode keys for this session
        explorer = Explorer(self.replay, n, self.s.explore_increment, self.s.explore_offset, self.building.band,
                            [self.mpc.layout.sensors.index(t) for t in self.mpc.layout.temperatures],
                            self.cfg.seed + self.steps, self.s.explore_hold,
                            self.building.steps_per_day) if self.replay else None  # fmt: skip
        rng = np.random.default_rng(self.cfg.seed + self.steps)
        batch = BatchComfort()
        while self.steps < self.cfg.timesteps:
            planning = self.steps >= self.s.explore_steps or explorer is None
            dagger = planning and self.s.distill and self.steps >= (1 - self.s.dagger_share) * self.cfg.timesteps
            if dagger and not self.student.fitted and self.student.rows >= DAGGER_MIN_ROWS:
                self.student.refit(self.mpc, self.cfg.seed + self.steps)
            if planning:
                planned = self.mpc.act(obs, infos, a_last)
                self.student.add(obs, planned, a_last, infos)
                actions = np.clip(planned + self.s.noise * rng.standard_normal(planned.shape), -1, 1).astype(np.float32)
                if dagger and self.student.fitted:  # the student acts; the planner takes over a worker far out of band
                    temps = obs[:, [self.mpc.layout.sensors.index(t) for t in self.mpc.layout.temperatures]]
                    low, high = self.building.band
                    far = np.any((temps < low - 2) | (temps > high + 2), axis=1)
                    actions = np.where(far[:, None], actions, self.student.actions(obs))
            else:
                actions = explorer.act(obs, infos, step_of)
                self.mpc.observe(obs, infos)  # the month's demand peaks, for when the planner takes over
            new_obs, _, dones, new_infos = venv.step(actions)
            for i in range(n):
                after = new_infos[i].get("final_info", new_infos[i]) if dones[i] else new_infos[i]
                nxt = new_infos[i].get("terminal_observation") if dones[i] else new_obs[i]
                if "time" in after and nxt is not None:  # a failed step (restarted episode) teaches nothing
                    self._add(obs[i], nxt, a_last[i], actions[i], after, episode_of[i], step_of[i], planning)
                    temps = [after[t] for t in self.building.temperatures]
                    if after.get("comfort_applies", True):
                        bounds = self.building.comfort.bounds(after)  # the thermostat's, where they move
                        own = self.own_level.count(after["weather"], after["time"]) if self.own_level else None
                        batch.add(self.building.comfort.outside(tuple(temps), bounds), len(temps), own, self.own_level)
                if dones[i]:
                    a_last[i], step_of[i], episode_of[i] = self.mpc.initial, 0, episode_of[i] + n
                    self.mpc.reset(i)
                    if explorer is not None:
                        explorer.reset(i)
                else:
                    a_last[i], step_of[i] = actions[i], step_of[i] + 1
            obs, infos = new_obs, new_infos
            self.steps += n
            self.shim.num_timesteps = self.steps
            for cb in self.callbacks:
                cb.update_locals({"infos": new_infos, "dones": dones})
                cb.on_step()
            if self.steps // self.s.refit_every != (self.steps - n) // self.s.refit_every:
                self._update_comfort(batch)
                batch = BatchComfort()
                self._refit(self.s.refit_epochs)
                if self.student.fitted:
                    self.student.refit(self.mpc, self.cfg.seed + self.steps)
                for cb in self.callbacks:
                    cb.on_rollout_end()
            if self.steps // self.cfg.checkpoint_every != (self.steps - n) // self.cfg.checkpoint_every:
                self._save_checkpoint()
            every = self.evaluator.settings.every if self.evaluator else 0
            if every and self.steps // every != (self.steps - n) // every:
                self._evaluate()
            if planning:
                self.logger.record_mean("planner/ms_per_step", self.mpc.last.ms)
                self.logger.record_mean("planner/cost", float(self.mpc.last.cost.mean()))

    def _evaluate(self) -> None:
        """`--eval-every`: the planner as it stands, saved and run frozen through `evaluate`'s own code."""
        from parallel_eplus.training.periodic_eval import record

        folder = self._save_planner()
        result = self.evaluator.evaluate_controller(
            planner_controller(str(folder)), self.steps, time.monotonic() - self._t0
        )
        best = self.cfg.run_dir / BEST_DIR / "planner"

        def save_best() -> None:
            shutil.rmtree(best, ignore_errors=True)
            shutil.copytree(folder, best)

        record(result, self.logger, save_best, self.cfg.run_dir)

    def _save_planner(self) -> Path:
        """runs/<name>/planner/: the planner and the run's settings (`evaluate` reads its building there)."""
        planner = self.mpc.save(self.cfg.run_dir / "planner" / PLANNER_FILE)
        io.write_text(planner.parent / "config.json", self.cfg.to_json())
        return planner.parent

    def _add(self, obs, nxt, a_prev, a, after: dict, episode: int, step: int, planning: bool) -> None:
        layout = self.mpc.layout
        applies = float(after.get("comfort_applies", True))
        times = self.mpc.comfort_times
        times.learn([after["time"]], [applies], times.bounds_of(after))
        x = self.mpc.exogenous_seen(self.mpc.forecasts.of(after), [after["time"]])
        sensors = len(layout.sensors)
        self.data.add(s=layout.state(obs[None, :sensors]), a_prev=a_prev[None], a=a[None], x=x,
                      s_next=layout.state(np.asarray(nxt)[None, :sensors]), applies=[applies], episode=[episode],
                      step=[step], origin=[ORIGINS.index("planner" if planning else "explore")])  # fmt: skip

    # -- the model, the comfort weight ----------------------------------------------------------
    def _record(self) -> None:
        days = self.s.record_days or (365 if self.cfg.random_start else self.cfg.run_days)  # dates to explore around
        self.replay, self.own_level = record_own_controls(self.cfg, days, self.data, self.mpc,
                                                          progress=not self.bar.disable)  # fmt: skip
        log.info("recorded the building's own controls: %d transitions", len(self.data))
        if self.own_level is not None:
            missing = [w for w in self.cfg.weathers if weather_label(w) not in self.own_level.out]
            if missing:  # those weathers' batches are held to the target alone (`comfort/own_unmatched_pct`)
                log.warning("comfort_level=baseline: the record has no steps on %s; there the target holds",
                            ", ".join(missing))  # fmt: skip
        jump = self.mpc.own_jump()
        if self.s.comfort_reference == "baseline" and jump > self.s.max_increment:
            log.warning(
                "comfort_reference=baseline: the building's own thermostats jump %.2f (normalized) in one "
                "step, beyond max_increment=%g: the planner reaches the occupied setpoint a step late and pays "
                "nothing for it; --mpc max_increment=2.0 lets it jump as they do",
                jump,
                self.s.max_increment,
            )

    def _refit(self, epochs: int) -> None:
        refit(self.mpc, self.data, self.building, self.s.horizon, epochs, self.logger, self.cfg.run_dir)
        self.logger.dump(self.steps)

    def _update_comfort(self, batch: BatchComfort) -> None:
        """The multiplier from the planner's batch, held to the own controls' level on its dates where asked."""
        if self.lagrangian is not None and self.steps > self.s.explore_steps and not self.student.fitted:
            allowed = batch.allowed_pct(self.lagrangian.settings.target_pct, self.own_level)
            self.mpc.comfort_weight = self.lagrangian.update(batch.out, batch.zones, allowed)
            self.lagrangian.record(self.logger)
            if self.own_level and batch.zones:
                self.logger.record("comfort/own_unmatched_pct", 100.0 * batch.unmatched / batch.zones)

    # -- checkpoints ----------------------------------------------------------------------------
    def _save_checkpoint(self) -> Path:
        extra = {"steps": self.steps, "lagrangian": None if self.lagrangian is None else self.lagrangian.multiplier,
                 "replay": {w: th.as_tensor(a) for w, a in self.replay.items()},
                 "own_level": None if self.own_level is None else self.own_level.state(tensors=True)}  # fmt: skip
        return self.checkpoints.save(self.steps, self.mpc, self.data, extra, self.student.arrays())

    def _restore(self, checkpoint: Path) -> None:
        state, self.data, policy = self.checkpoints.load(checkpoint, self.mpc.layout)
        self.mpc = MPC.from_state(state["mpc"], self.venv.num_envs, self.cfg.seed + state["steps"])
        self.data.layout = self.mpc.layout
        self.steps = state["steps"]
        self.replay = {w: np.asarray(a) for w, a in state["replay"].items()}
        if self.s.comfort_level == "baseline":
            if state.get("own_level") is None:
                raise ValueError(
                    f"--resume with comfort_level=baseline: {checkpoint} has no record of the building's "
                    "own comfort (a run started without it); start a new run"
                )
            self.own_level = OwnLevel.from_state(state["own_level"])
        if self.lagrangian is not None and state["lagrangian"] is not None:
            self.lagrangian.multiplier = state["lagrangian"]
        self.student.restore(policy)
        log.info("resuming %s from %s at step %d (%d transitions)", self.cfg.run_name, checkpoint, self.steps,
                 len(self.data))  # fmt: skip


__all__ = ["train_mpc", "newest_checkpoint"]
