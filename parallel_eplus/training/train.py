"""The learner: sb3-contrib TRPO with the paper's settings over N EnergyPlus workers.

Run output: `runs/<run-name>/` (config.json, checkpoints/, model.zip + vecnormalize.npz, episodes.csv
and the newest episode directories) and `tensorboard_logs/<run-name>/` (TensorBoard events).
"""

from __future__ import annotations

import logging
import math
from collections.abc import Sequence
from pathlib import Path

import pandas as pd
import torch as th
from stable_baselines3.common.callbacks import BaseCallback, CallbackList
from stable_baselines3.common.vec_env import VecNormalize
from tqdm import tqdm

from parallel_eplus import io
from parallel_eplus.buildings.building import Building
from parallel_eplus.engine.config import SimulationConfig
from parallel_eplus.envs.vector_env import EnergyPlusVectorEnv, weather_shares
from parallel_eplus.errors import EnergyPlusError, Interrupts
from parallel_eplus.learning.lagrangian import ConstrainedRolloutBuffer, CostReplayBuffer, Lagrangian, SACComfort
from parallel_eplus.learning.sb3_adapter import SB3VecEnv
from parallel_eplus.runs.checkpoints import AtomicCheckpoint, save_checkpoint
from parallel_eplus.runs.norm_stats import read_stats
from parallel_eplus.runs.policy_files import (
    MODEL_FILE,
    _warm_start,
    normalization_file,
    replay_buffer_file,
)
from parallel_eplus.runs.run_status import RunStatus
from parallel_eplus.training.callbacks import (
    BUILTIN_FILE,
    EpisodeMetrics,
    UpdateTimer,
    episodes_per_weather,
    tensorboard_logger,
)
from parallel_eplus.training.config import TrainConfig
from parallel_eplus.training.resume_settings import load_kwargs
from parallel_eplus.training.run_setup import episodes_done, prepare_run

log = logging.getLogger(__name__)


def sim_config(cfg: TrainConfig) -> SimulationConfig:
    """What each training worker simulates (the first weather; the workers' shares cycle the others)."""
    return SimulationConfig(
        weather=cfg.weathers[0],
        model=cfg.model,
        building=cfg.building,
        run_days=cfg.run_days,
        random_start=cfg.random_start,
        prepare_next=cfg.prepare_next,
        fork_episodes=cfg.fork_episodes,
        output_dir=str(cfg.run_dir / "episodes"),
        keep_episodes=cfg.keep_episodes,
        energyplus_csv=False,  # the kept episodes' records are steps.parquet
        reward=cfg.reward,
        time_features=cfg.time_features,
        schedule_features=cfg.schedule_features,
        residual_scale=cfg.residual_scale,
        residual_space=cfg.residual_space,
        rbc_target_c=cfg.rbc_target_c,
        step_timeout_s=cfg.step_timeout_s,
        comfort_margin_c=cfg.comfort.margin_c if cfg.constrained else None,
        objective=cfg.objective,
        weather_noise=cfg.weather_noise,
        seed=cfg.seed,
        forecast_hours=cfg.forecast_hours,
        forecast_error=cfg.forecast_error,
    )


def make_vec_env(cfg: TrainConfig, building: Building | None = None) -> SB3VecEnv:
    """The workers as SB3 sees them: local processes or Ray actors behind one VecEnv. `building`: the run's, as
    `train` resolved it (None: resolved from the config; a Ray actor resolves its own)."""
    sim = sim_config(cfg)
    shares = weather_shares(cfg.weathers, cfg.workers, episodes_done(cfg.run_dir / "episodes.csv", cfg.workers))
    if cfg.backend == "ray":
        from parallel_eplus.learning.ray_vector_env import RayVectorEnv

        per_actor = cfg.workers_per_actor or cfg.workers
        venv = RayVectorEnv(sim, shares, per_actor, cfg.ray_address, cfg.max_restarts)
    else:
        venv = EnergyPlusVectorEnv(sim, shares, max_restarts=cfg.max_restarts, building=building)
    return SB3VecEnv(venv)


def train(
    cfg: TrainConfig,
    resume: str | Path | None = None,
    progress: bool = True,
    timer: UpdateTimer | None = None,
    overwrite: bool = False,
    callbacks: Sequence[BaseCallback] = (),
) -> Path:
    """Train (or resume) and return the final model's path. Ctrl-C/SIGTERM saves a checkpoint first.

    A new run whose name is taken is refused, or with `overwrite` the old one is moved aside (run_names.py).
    `callbacks` run after ours (a sweep's trial reports each batch to Ray Tune with one: experiments/tune_trial.py).
    runs/<name>/status.json says how far it got and how it ended (run_status.py; `parallel-eplus runs`).
    """
    cfg, checkpoint, building = prepare_run(cfg, resume, overwrite)  # the one resolution of the run's building
    if cfg.algorithm == "mpc":  # the model-based learner drives the same workers itself
        from parallel_eplus.training.mpc import train_mpc

        return train_mpc(cfg, checkpoint, progress, make_vec_env, _new_model, callbacks, _evaluator(cfg, building))
    with RunStatus(cfg.run_dir, cfg.timesteps) as status:
        return _learn(cfg, building, checkpoint, progress, timer, status, callbacks)


def _learn(
    cfg: TrainConfig, building: Building, checkpoint: Path | None, progress: bool, timer: UpdateTimer | None,
    status: RunStatus, callbacks: Sequence[BaseCallback] = (),
) -> Path:  # fmt: skip
    from parallel_eplus.learning.algorithms import ALGORITHMS
    from parallel_eplus.learning.saved_models import load_model

    run_dir = cfg.run_dir
    th.set_num_threads(1)  # the cores belong to EnergyPlus; the 32x32 policy needs no more
    venv = make_vec_env(cfg, building)
    bar = None
    try:
        if checkpoint is not None:
            env = read_stats(normalization_file(checkpoint)).wrap(venv)
            model = load_model(ALGORITHMS[cfg.algorithm], checkpoint, env=env, device="cpu", **load_kwargs(cfg))
            _load_replay_buffer(model, checkpoint)
            log.info("resuming %s from %s at step %d", cfg.run_name, checkpoint, model.num_timesteps)
        else:
            env = VecNormalize(venv, norm_obs=True, norm_reward=False, gamma=cfg.trpo.gamma)
            model = _new_model(cfg, env)
            if cfg.init_from is not None and cfg.algorithm != "mbpo":  # mbpo's: a planner run's model and data
                _warm_start(Path(cfg.init_from), model, env)
                log.info("%s starts from the weights of %s", cfg.run_name, cfg.init_from)
            if cfg.init_from_baseline:
                _clone_baseline(cfg, building, model, env, progress)
        if cfg.off_policy:  # a cloned actor acts its warm-up (guarded_sac.py)
            model.warmup_policy = cfg.init_from_baseline
        model.lockstep = cfg.lockstep
        model.overlap = cfg.overlap
        model.set_logger(tensorboard_logger(Path(cfg.tensorboard_dir) / str(cfg.run_name)))
        start_steps = model.num_timesteps
        remaining = max(cfg.timesteps - model.num_timesteps, 0)
        batch = cfg.workers if cfg.off_policy else cfg.n_steps * cfg.workers
        model_based = None
        if cfg.algorithm == "mbpo":  # (imported here: the ensemble's modules are not every run's)
            from parallel_eplus.training.mbpo import model_rollouts

            model_based = model_rollouts(cfg, venv, checkpoint, progress)
        end = model.num_timesteps + math.ceil(remaining / batch) * batch  # SB3 finishes whole batches
        status.write(steps=model.num_timesteps, planned=end)
        bar = tqdm(total=end, initial=model.num_timesteps, unit="step", disable=not progress,
                   desc=f"train {cfg.run_name}", smoothing=0.05)  # fmt: skip
        chain = CallbackList([
            timer or UpdateTimer(),
            EpisodeMetrics(run_dir / "episodes.csv", bar, 365 * building.steps_per_day),
            AtomicCheckpoint(max(cfg.checkpoint_every // cfg.workers, 1), run_dir / "checkpoints"),
            *([SACComfort(cfg.batch_size)] if cfg.constrained and cfg.off_policy else []),
            *([model_based] if model_based is not None else []),
            status,
            *_evaluation(cfg, building, model, env),
            *callbacks,
        ])  # fmt: skip
        try:
            with Interrupts():
                model.learn(remaining, callback=chain, reset_num_timesteps=False, log_interval=1)
        except (KeyboardInterrupt, EnergyPlusError) as e:
            if isinstance(e, EnergyPlusError) and model.num_timesteps == start_steps:
                raise  # nothing learned since the last save
            path = save_checkpoint(model, env, run_dir / "checkpoints" / f"model_{model.num_timesteps}_steps.zip", True)
            if model_based is not None:
                model_based.save()
            cause = "interrupted" if isinstance(e, KeyboardInterrupt) else "stopped by the failure below"
            log.warning("%s at step %d; checkpoint saved: %s", cause, model.num_timesteps, path)
            log.warning("resume with: parallel-eplus train --resume %s", path)
            raise
        final = save_checkpoint(model, env, run_dir / MODEL_FILE, replay_buffer=True)
        counts = episodes_per_weather(run_dir / "episodes.csv")
        log.info("%s: %d steps; episodes per weather: %s", cfg.run_name, model.num_timesteps,
                 ", ".join(f"{w} {n}" for w, n in counts.items()) or "none finished")  # fmt: skip
        return final
    finally:
        if bar is not None:
            bar.close()
        venv.close()


def _evaluation(cfg: TrainConfig, building: Building, model, env: VecNormalize) -> list[BaseCallback]:
    """`--eval-every`: the frozen policy on the validation weathers between batches (training/periodic_eval.py)."""
    if not cfg.evaluation.every:
        return []
    from parallel_eplus.training.periodic_eval import PeriodicEval

    return [PeriodicEval(_evaluator(cfg, building), (cfg.time_features, cfg.schedule_features),
                         lambda path: save_checkpoint(model, env, path))]  # fmt: skip


def _evaluator(cfg: TrainConfig, building: Building):
    """`--eval-every`'s evaluator (training/periodic_eval.py), for any algorithm; None without the option."""
    if not cfg.evaluation.every:
        return None
    from parallel_eplus.training.periodic_eval import Evaluator

    return Evaluator(cfg.run_dir, cfg.evaluation, sim_config(cfg), cfg.weathers, cfg.workers, building)


def _load_replay_buffer(model, checkpoint: Path) -> None:
    if not hasattr(model, "load_replay_buffer"):
        return
    path = replay_buffer_file(checkpoint)
    if path.is_file():
        model.load_replay_buffer(path)
        log.info("replay buffer restored: %d transitions", model.replay_buffer.size() * model.n_envs)
    else:
        log.warning("%s has no replay buffer beside it (periodic checkpoints leave it out): SAC resumes with an "
                    "empty buffer and updates from it at once", checkpoint.name)  # fmt: skip


def _clone_baseline(cfg: TrainConfig, building: Building, model, env: VecNormalize, progress: bool) -> None:
    """`--init-from-baseline`: fit the new policy to the building's own controls on the training weathers; the
    cloned policy is saved in runs/<name>/cloned/ (evaluate it to see how close it gets before any RL)."""
    import json
    import shutil

    from parallel_eplus.learning.imitation import clone, record_baseline

    days = cfg.imitation.run_days or cfg.run_days
    work = cfg.run_dir / "baseline-record"
    demos = record_baseline(cfg.building, cfg.weathers, days, cfg.workers, work,
                            (cfg.time_features, cfg.schedule_features), progress, cfg.forecast_hours)  # fmt: skip
    if days == cfg.run_days and demos.builtin:  # the built-in's figures: episodes' ratios to them (callbacks.py)
        io.write_text(cfg.run_dir / BUILTIN_FILE, pd.DataFrame(demos.builtin).to_csv(index=False))
    regulated = [building.sensor_names.index(t) for t in building.temperatures]
    report = clone(model, env, demos, cfg.imitation, cfg.seed, regulated, building.band)
    shutil.rmtree(work, ignore_errors=True)  # a year's EnergyPlus CSV per weather: the fit is what is kept
    report |= {"weathers": cfg.weathers, "days_per_weather": days}
    io.write_text(cfg.run_dir / "imitation.json", json.dumps(report, indent=2))
    cloned = cfg.run_dir / "cloned"
    save_checkpoint(model, env, cloned / MODEL_FILE)
    io.write_text(cloned / "config.json", cfg.to_json())  # so `evaluate --policy` reads its building
    rmse = ", ".join(f"{k} {v:.3g}" for k, v in report["rmse"].items())
    log.info("cloned the built-in controls from %d steps (RMSE, physical units: %s); saved: %s",
             report["samples"], rmse, cloned / MODEL_FILE)  # fmt: skip


def _new_model(cfg: TrainConfig, env: VecNormalize):
    model = _algorithm(cfg, env)
    if cfg.constrained:
        model.comfort = Lagrangian.start(cfg.comfort)  # saved with the model: --resume restores it
    return model


def _algorithm(cfg: TrainConfig, env: VecNormalize):
    from parallel_eplus.learning.algorithms import ALGORITHMS

    if cfg.off_policy:
        s = cfg.sac
        buffer = {"replay_buffer_class": CostReplayBuffer} if cfg.constrained else {}
        learning_starts, gradient_steps = s.learning_starts, s.gradient_steps
        if cfg.algorithm == "mbpo":  # the model's rollouts are data from the first step; more updates per step
            from parallel_eplus.learning.model_based.mbpo.buffer import ModelMixBuffer

            buffer = {"replay_buffer_class": ModelMixBuffer,
                      "replay_buffer_kwargs": {"model_size": cfg.mbpo.model_buffer}}  # fmt: skip
            learning_starts, gradient_steps = 0, cfg.mbpo.gradient_steps
        return ALGORITHMS[cfg.algorithm](
            "MlpPolicy", env, learning_rate=s.learning_rate, buffer_size=s.buffer_size,
            learning_starts=learning_starts, batch_size=s.batch_size, tau=s.tau, gamma=s.gamma,
            train_freq=s.train_freq, gradient_steps=gradient_steps, ent_coef=s.ent_coef, seed=cfg.seed,
            device="cpu", policy_kwargs={"net_arch": list(s.net_arch)}, **buffer,
        )  # fmt: skip

    t = cfg.trpo
    common = dict(
        n_steps=cfg.n_steps, gamma=t.gamma, gae_lambda=t.gae_lambda, seed=cfg.seed, device="cpu",
        rollout_buffer_class=ConstrainedRolloutBuffer if cfg.constrained else None,
        use_sde=t.sde_sample_freq > 0, sde_sample_freq=t.sde_sample_freq if t.sde_sample_freq > 0 else -1,
        # Fused Adam: the same update in one kernel per step instead of a Python loop over the tensors.
        # The critic takes 1,280 minibatch steps per 16k batch; this cut the update by a quarter (2.3 -> 1.7 s).
        policy_kwargs={
            "net_arch": list(t.net_arch), "activation_fn": th.nn.Tanh, "log_std_init": t.log_std_init,
            "optimizer_kwargs": {"fused": True},
        },
    )  # fmt: skip
    if cfg.algorithm == "ppo":
        p = cfg.ppo
        return ALGORITHMS["ppo"](
            "MlpPolicy", env, learning_rate=p.learning_rate, n_epochs=p.n_epochs, batch_size=p.batch_size,
            clip_range=p.clip_range, **common,
        )  # fmt: skip
    return ALGORITHMS["trpo"](
        "MlpPolicy", env, learning_rate=t.learning_rate, batch_size=t.critic_batch_size, cg_max_steps=t.cg_max_steps,
        cg_damping=t.cg_damping, n_critic_updates=t.n_critic_updates, target_kl=t.target_kl, **common,
    )  # fmt: skip
