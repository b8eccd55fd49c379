"""The learner: sb3-contrib TRPO with the paper's settings over N EnergyPlus workers.

Run output: `runs/<run-name>/` (config.json, checkpoints/, model.zip + vecnormalize.pkl, episodes.csv
and the newest episode directories) and `tensorboard_logs/<run-name>/` (TensorBoard events).
"""

from __future__ import annotations

import json
import logging
import math
import os
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd
import torch as th
from stable_baselines3.common.callbacks import BaseCallback, CallbackList, CheckpointCallback
from stable_baselines3.common.logger import configure
from stable_baselines3.common.vec_env import VecNormalize
from tqdm import tqdm

from .errors import Interrupts
from .model import STEPS_PER_DAY, observation_names
from .reward import RewardConfig
from .sb3_adapter import SB3VecEnv
from .simulation import RESIDUAL_SPACES, SimulationConfig
from .vector_env import EnergyPlusVectorEnv, weather_shares
from .weather import parse_weathers

log = logging.getLogger(__name__)

MODEL_FILE = "model.zip"
NORMALIZE_FILE = "vecnormalize.pkl"
STEPS_PER_YEAR = 365 * STEPS_PER_DAY


@dataclass
class TRPOSettings:
    """The paper's TRPO hyperparameters (Section 5.1.4), as sb3-contrib names them."""

    net_arch: tuple[int, ...] = (32, 32)  # tanh MLP
    target_kl: float = 0.01  # max_KL
    cg_max_steps: int = 10  # cg_iters
    cg_damping: float = 0.1
    gamma: float = 0.99
    gae_lambda: float = 0.98  # lam
    n_critic_updates: int = 5  # vf_iters
    learning_rate: float = 1e-3  # vf_stepsize
    critic_batch_size: int = 64  # OpenAI Baselines' value-function minibatch
    # The Gaussian policy's initial log standard deviation (SB3's default, 0, is the paper's too). A residual
    # policy starts from a working controller, where noise of one action unit would unsettle it.
    log_std_init: float = 0.0


@dataclass
class PPOSettings:
    """Stable-Baselines3's PPO for comparison runs; network, gamma and GAE lambda come from TRPOSettings."""

    learning_rate: float = 3e-4
    n_epochs: int = 10
    batch_size: int = 256  # minibatch
    clip_range: float = 0.2


@dataclass
class TrainConfig:
    """Everything a training run needs; saved as runs/<name>/config.json."""

    workers: int = field(default_factory=lambda: os.cpu_count() or 1)
    weathers: list[str] = field(default_factory=lambda: ["CA"])
    model: str = "temp_fan"
    timesteps: int = 1_000_000
    run_days: int = 365
    batch_size: int = 16384  # the paper's timesteps_per_batch, split evenly across workers
    seed: int = 0
    run_name: str | None = None
    runs_dir: str = "runs"
    tensorboard_dir: str = "tensorboard_logs"
    checkpoint_every: int = 100_000  # env steps
    keep_episodes: int = 2  # full episode directories kept per worker
    backend: str = "local"  # or "ray"
    ray_address: str | None = None
    workers_per_actor: int | None = None  # Ray: EnergyPlus workers per actor (default: all on one)
    max_restarts: int = 3
    # True: every worker waits for the slowest at each step (SB3's way; a seed fixes the run bit for bit).
    # False: each local worker gets its next action as soon as its observation arrives (rollout.py).
    lockstep: bool = False
    time_features: bool = False  # opt-in hour/weekday observation features (model.TIME_FEATURES)
    schedule_features: bool = False  # opt-in IT-load schedule features (model.SCHEDULE_FEATURES)
    init_from: str | None = None  # a saved model.zip whose weights and observation statistics start this run
    algorithm: str = "trpo"  # the paper's; or "ppo"
    residual_scale: float = 0.0  # > 0: the policy corrects the rule-based controller (SimulationConfig)
    residual_space: str = "action"  # what it corrects: each action, or each zone's flow demand (SimulationConfig)
    rbc_target_c: float | None = None  # that controller's zone target; None: RBCConfig's
    reward: RewardConfig = field(default_factory=RewardConfig)
    trpo: TRPOSettings = field(default_factory=TRPOSettings)
    ppo: PPOSettings = field(default_factory=PPOSettings)

    def resolved(self) -> TrainConfig:
        """Validate, and fill in the run name."""
        parse_weathers(",".join(self.weathers))
        if self.workers < 1:
            raise ValueError("--workers must be at least 1")
        if self.batch_size < self.workers:
            raise ValueError("--batch-size must be at least the number of workers")
        if self.init_from is not None:
            self.init_from = str(Path(self.init_from).resolve())
        if self.algorithm not in ("trpo", "ppo"):
            raise ValueError(f"unknown algorithm {self.algorithm!r}: use trpo or ppo")
        if self.residual_scale < 0 or (self.residual_scale and self.model != "temp_fan"):
            raise ValueError("--residual needs a scale >= 0 and --model temp_fan (it corrects all four actions)")
        if self.residual_space not in RESIDUAL_SPACES:
            raise ValueError(f"unknown --residual-space {self.residual_space!r}: use {' or '.join(RESIDUAL_SPACES)}")
        if self.residual_space != "action" and not self.residual_scale:
            raise ValueError(f"--residual-space {self.residual_space} needs --residual SCALE (kg/s of demand per unit)")
        if self.backend not in ("local", "ray"):
            raise ValueError(f"unknown backend {self.backend!r}: use local or ray")
        if self.run_name is None:
            self.run_name = f"{self.algorithm}-{'-'.join(self.weathers)}-{time.strftime('%Y%m%d-%H%M%S')}"
        # Absolute, so a resumed run writes to the same places from any working directory.
        self.runs_dir = str(Path(self.runs_dir).resolve())
        self.tensorboard_dir = str(Path(self.tensorboard_dir).resolve())
        return self

    @property
    def run_dir(self) -> Path:
        return Path(self.runs_dir) / str(self.run_name)

    @property
    def n_steps(self) -> int:
        """Steps per worker per batch."""
        return math.ceil(self.batch_size / self.workers)

    def to_json(self) -> str:
        return json.dumps(asdict(self), indent=2)

    @classmethod
    def from_json(cls, text: str) -> TrainConfig:
        raw = json.loads(text)
        raw["reward"] = RewardConfig(**raw["reward"])
        raw["trpo"] = TRPOSettings(**{**raw["trpo"], "net_arch": tuple(raw["trpo"]["net_arch"])})
        raw["ppo"] = PPOSettings(**raw.get("ppo", {}))  # runs from before PPO have none
        return cls(**raw)


def make_vec_env(cfg: TrainConfig) -> SB3VecEnv:
    """The workers as SB3 sees them: local processes or Ray actors behind one VecEnv."""
    sim = SimulationConfig(
        weather=cfg.weathers[0],
        model=cfg.model,
        run_days=cfg.run_days,
        output_dir=str(cfg.run_dir / "episodes"),
        keep_episodes=cfg.keep_episodes,
        reward=cfg.reward,
        time_features=cfg.time_features,
        schedule_features=cfg.schedule_features,
        residual_scale=cfg.residual_scale,
        residual_space=cfg.residual_space,
        rbc_target_c=cfg.rbc_target_c,
    )
    shares = weather_shares(cfg.weathers, cfg.workers, _episodes_done(cfg.run_dir / "episodes.csv", cfg.workers))
    if cfg.backend == "ray":
        from .ray_backend import RayVectorEnv

        per_actor = cfg.workers_per_actor or cfg.workers
        venv = RayVectorEnv(sim, shares, per_actor, cfg.ray_address, cfg.max_restarts)
    else:
        venv = EnergyPlusVectorEnv(sim, shares, max_restarts=cfg.max_restarts)
    return SB3VecEnv(venv)


def _episodes_done(episodes_csv: Path, workers: int) -> list[int]:
    """Finished episodes per worker so far (a resumed run continues each worker's weather cycle)."""
    if not episodes_csv.is_file():
        return [0] * workers
    counts = pd.read_csv(episodes_csv, usecols=["worker"])["worker"].value_counts()
    return [int(counts.get(i, 0)) for i in range(workers)]


def episodes_per_weather(episodes_csv: Path) -> dict[str, int]:
    """The run's finished episodes by weather, from its episodes.csv."""
    if not episodes_csv.is_file():
        return {}
    counts = pd.read_csv(episodes_csv, usecols=["weather"])["weather"].value_counts().sort_index()
    return {str(k): int(v) for k, v in counts.items()}


class EpisodeMetrics(BaseCallback):
    """Per finished episode, tagged by weather: reward, power, zone temperatures, share in range.

    Also appends every episode's summary to runs/<name>/episodes.csv and logs throughput.
    """

    KEYS = {
        "reward_mean": "reward_per_step",
        "power_kw": "power_kw",
        "it_power_kw": "it_power_kw",
        "hvac_power_kw": "hvac_power_kw",
        "west_temp_mean": "west_temp_mean",
        "west_temp_std": "west_temp_std",
        "east_temp_mean": "east_temp_mean",
        "east_temp_std": "east_temp_std",
        "in_band_pct": "in_22_25_pct",
    }

    def __init__(self, episodes_csv: Path, progress: tqdm | None):
        super().__init__()
        self.episodes_csv = episodes_csv
        self.progress = progress
        self.episodes = 0
        self.per_weather = episodes_per_weather(episodes_csv)  # a resumed run counts on from its earlier episodes
        self._t0 = time.monotonic()
        self._steps0 = 0

    def _on_training_start(self) -> None:
        self._t0 = time.monotonic()
        self._steps0 = self.num_timesteps

    def _on_step(self) -> bool:
        for info in self.locals["infos"]:
            final = info.get("final_info")
            if final and "episode_summary" in final:
                self._record(final["episode_summary"], info.get("episode", {}).get("r"))
        if self.progress is not None:
            self.progress.update(self.training_env.num_envs)
        return True

    def _record(self, summary: dict, episode_return: float | None) -> None:
        self.episodes += 1
        weather = summary.get("weather", "?")
        self.per_weather[weather] = self.per_weather.get(weather, 0) + 1
        for key, tag in self.KEYS.items():
            if key in summary:
                self.logger.record_mean(f"episode/{weather}/{tag}", summary[key])
        if episode_return is not None:
            self.logger.record_mean(f"episode/{weather}/return", episode_return)
        row = {"timesteps": self.num_timesteps, **summary}
        pd.DataFrame([row]).to_csv(self.episodes_csv, mode="a", header=not self.episodes_csv.exists(), index=False)
        if self.progress is not None:
            self.progress.set_postfix(episodes=self.episodes, last=f"{weather} {summary.get('power_kw', 0):.0f} kW")

    def _on_rollout_end(self) -> None:
        elapsed = time.monotonic() - self._t0
        if elapsed > 0:
            rate = (self.num_timesteps - self._steps0) / elapsed
            self.logger.record("throughput/env_steps_per_s", rate)
            self.logger.record("throughput/sim_years_per_hour", rate * 3600 / STEPS_PER_YEAR)
        self.logger.record("throughput/episodes", self.episodes)
        for weather, count in self.per_weather.items():
            self.logger.record(f"episodes/{weather}", count)


def _latest_checkpoint(path: Path) -> Path:
    """A checkpoint .zip, or the newest save in a run directory: the last checkpoint, or the final model
    when the run finished after it (SB3 ends on a whole batch, past the last checkpoint)."""
    if path.is_file():
        return path
    checkpoints = sorted((path / "checkpoints").glob("model_*_steps.zip"), key=lambda p: int(p.stem.split("_")[1]))
    saves = checkpoints[-1:] + [p for p in [path / MODEL_FILE] if p.is_file()]
    if not saves:
        raise FileNotFoundError(f"no checkpoint or {MODEL_FILE} in {path}")
    return max(saves, key=lambda p: p.stat().st_mtime_ns)


def normalization_file(model_zip: Path) -> Path:
    """The VecNormalize statistics saved beside a model or checkpoint."""
    if model_zip.name == MODEL_FILE:
        return model_zip.with_name(NORMALIZE_FILE)
    steps = model_zip.stem.split("_")[1]
    return model_zip.with_name(f"model_vecnormalize_{steps}_steps.pkl")


def run_dir_of(checkpoint: Path) -> Path:
    return checkpoint.parent.parent if checkpoint.parent.name == "checkpoints" else checkpoint.parent


class UpdateTimer(BaseCallback):
    """Wall time of each TRPO update (between rollouts), and of `learn` from the first observations on."""

    def __init__(self):
        super().__init__()
        self.updates: list[float] = []
        self._t: float | None = None
        self.learn_s = 0.0
        self.learn_steps = 0

    def _on_training_start(self) -> None:  # SB3 has reset the env: every worker has its first observation
        self._t0, self._steps0 = time.perf_counter(), self.num_timesteps

    def _on_training_end(self) -> None:
        self._update_done()  # the last rollout's update, which no rollout follows
        self.learn_s = time.perf_counter() - self._t0
        self.learn_steps = self.num_timesteps - self._steps0

    def _on_rollout_end(self) -> None:
        self._t = time.perf_counter()

    def _on_rollout_start(self) -> None:
        self._update_done()

    def _update_done(self) -> None:
        if self._t is not None:
            self.updates.append(time.perf_counter() - self._t)
            self.logger.record("throughput/update_s", self.updates[-1])
            self._t = None

    def _on_step(self) -> bool:
        return True


def train(
    cfg: TrainConfig,
    resume: str | Path | None = None,
    progress: bool = True,
    timer: UpdateTimer | None = None,
) -> Path:
    """Train (or resume) and return the final model's path. Ctrl-C/SIGTERM saves a checkpoint first."""
    from .rollout import ALGORITHMS

    checkpoint = None
    if resume is not None and cfg.init_from is not None:
        raise ValueError("--resume continues a run; --init-from starts a new one from a policy: pass one of them")
    if resume is not None:
        checkpoint = _latest_checkpoint(Path(resume))
        saved = TrainConfig.from_json((run_dir_of(checkpoint) / "config.json").read_text())
        # The run keeps its settings (the rollout buffer is sized by them); only where it runs may change.
        saved.timesteps = cfg.timesteps or saved.timesteps
        saved.backend, saved.ray_address, saved.lockstep = cfg.backend, cfg.ray_address, cfg.lockstep
        cfg = saved
    cfg = cfg.resolved()
    if cfg.init_from is not None and checkpoint is None:  # a resumed run has its weights already
        _check_init_from(Path(cfg.init_from), (cfg.time_features, cfg.schedule_features))  # before EnergyPlus starts
    run_dir = cfg.run_dir
    run_dir.mkdir(parents=True, exist_ok=True)
    (run_dir / "config.json").write_text(cfg.to_json())
    th.set_num_threads(1)  # the cores belong to EnergyPlus; the 32x32 policy needs no more

    venv = make_vec_env(cfg)
    bar = None
    try:
        if checkpoint is not None:
            env = VecNormalize.load(str(normalization_file(checkpoint)), venv)
            model = ALGORITHMS[cfg.algorithm].load(checkpoint, env=env, device="cpu")
            log.info("resuming %s from %s at step %d", cfg.run_name, checkpoint, model.num_timesteps)
        else:
            env = VecNormalize(venv, norm_obs=True, norm_reward=False, gamma=cfg.trpo.gamma)
            model = _new_model(cfg, env)
            if cfg.init_from is not None:
                _warm_start(Path(cfg.init_from), model, env)
                log.info("%s starts from the weights of %s", cfg.run_name, cfg.init_from)
        model.lockstep = cfg.lockstep
        model.set_logger(configure(str(Path(cfg.tensorboard_dir) / str(cfg.run_name)), ["tensorboard"]))
        remaining = max(cfg.timesteps - model.num_timesteps, 0)
        batch = cfg.n_steps * cfg.workers
        end = model.num_timesteps + math.ceil(remaining / batch) * batch  # SB3 finishes whole batches
        bar = tqdm(total=end, initial=model.num_timesteps, unit="step", disable=not progress,
                   desc=f"train {cfg.run_name}", smoothing=0.05)  # fmt: skip
        callbacks = CallbackList([
            timer or UpdateTimer(),
            EpisodeMetrics(run_dir / "episodes.csv", bar),
            CheckpointCallback(
                save_freq=max(cfg.checkpoint_every // cfg.workers, 1),
                save_path=str(run_dir / "checkpoints"),
                name_prefix="model",
                save_vecnormalize=True,
            ),
        ])  # fmt: skip
        try:
            with Interrupts():
                model.learn(remaining, callback=callbacks, reset_num_timesteps=False, log_interval=1)
        except KeyboardInterrupt:
            path = run_dir / "checkpoints" / f"model_{model.num_timesteps}_steps.zip"
            path.parent.mkdir(parents=True, exist_ok=True)
            model.save(path)
            env.save(str(normalization_file(path)))
            log.warning("interrupted at step %d; checkpoint saved: %s", model.num_timesteps, path)
            log.warning("resume with: parallel-eplus train --resume %s", path)
            raise
        final = run_dir / MODEL_FILE
        model.save(final)
        env.save(str(run_dir / NORMALIZE_FILE))
        counts = episodes_per_weather(run_dir / "episodes.csv")
        log.info("%s: %d steps; episodes per weather: %s", cfg.run_name, model.num_timesteps,
                 ", ".join(f"{w} {n}" for w, n in counts.items()) or "none finished")  # fmt: skip
        return final
    finally:
        if bar is not None:
            bar.close()
        venv.close()


def _new_model(cfg: TrainConfig, env: VecNormalize):
    from .rollout import ALGORITHMS

    t = cfg.trpo
    common = dict(
        n_steps=cfg.n_steps, gamma=t.gamma, gae_lambda=t.gae_lambda, seed=cfg.seed, device="cpu",
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


def _saved_policy(model_zip: Path):
    """The policy network of a saved model, whichever on-policy algorithm trained it."""
    from stable_baselines3.common.save_util import load_from_zip_file

    data, params, _ = load_from_zip_file(model_zip, device="cpu")
    policy = data["policy_class"](
        data["observation_space"], data["action_space"], lambda _: 0.0, **data["policy_kwargs"]
    )
    policy.load_state_dict(params["policy"])
    policy.set_training_mode(False)
    return policy


def require_policy_files(model_zip: Path, context: str = "") -> Path:
    """A saved policy is two files: the model and its observation statistics; returns the latter."""
    if not model_zip.is_file():
        raise FileNotFoundError(f"{context}policy not found: {model_zip}")
    stats = normalization_file(model_zip)
    if not stats.is_file():
        raise FileNotFoundError(f"{context}observation statistics missing beside the policy: {stats}")
    return stats


def _check_init_from(model_zip: Path, features: tuple[bool, bool]) -> None:
    require_policy_files(model_zip, "--init-from: ")
    saved = policy_features(model_zip)
    old, new = observation_names(*saved), observation_names(*features)
    if new[: len(old)] != old:
        flags = [f for f, on in zip(("--time-features", "--schedule-features"), saved, strict=True) if on]
        trained = f"with {' and '.join(flags)}" if flags else "without --time-features or --schedule-features"
        raise ValueError(
            f"--init-from {model_zip}: that policy was trained {trained}; pass the same flags (more may be added)"
        )


def _warm_start(model_zip: Path, model, env: VecNormalize) -> None:
    """The saved policy's weights and observation statistics, into a run that may observe more.

    Observations added after the saved policy's own (`--schedule-features` on a policy trained with
    `--time-features`, say) enter its first layers with zero weights, so the run starts from exactly
    the saved policy's behaviour; their statistics start at mean 0, variance 1 and keep updating.
    """
    import pickle

    state = model.policy.state_dict()
    for key, value in _saved_policy(model_zip).state_dict().items():
        target = state.get(key)
        if target is not None and value.ndim == target.ndim == 2 and target.shape[1] > value.shape[1]:
            # An input layer over more observations (a wrong row count still fails in load_state_dict).
            value = th.cat([value, th.zeros(value.shape[0], target.shape[1] - value.shape[1])], dim=1)
        state[key] = value
    try:
        model.policy.load_state_dict(state)
    except RuntimeError as e:  # another network shape
        raise ValueError(f"--init-from {model_zip}: its network does not fit this run's: {e}") from e
    with open(normalization_file(model_zip), "rb") as f:
        stats = pickle.load(f).obs_rms
    n = len(stats.mean)
    env.obs_rms.mean[:n], env.obs_rms.var[:n], env.obs_rms.count = stats.mean, stats.var, stats.count


def policy_features(model_zip: str | Path) -> tuple[bool, bool]:
    """Whether a saved policy observes (`model.TIME_FEATURES`, `model.SCHEDULE_FEATURES`), read from
    the size of its observation statistics."""
    import pickle

    with open(normalization_file(Path(model_zip)), "rb") as f:
        norm: VecNormalize = pickle.load(f)
    n = norm.observation_space.shape[0]
    options = [(t, s) for t in (False, True) for s in (False, True)]
    found = [o for o in options if len(observation_names(*o)) == n]
    if not found:
        raise ValueError(f"{model_zip}: a policy over {n} observations does not fit this model")
    return found[0]


def load_policy(model_zip: str | Path):
    """A trained policy and its observation normalizer, ready to act deterministically."""
    model_zip = Path(model_zip)
    stats = require_policy_files(model_zip)
    saved = _saved_policy(model_zip)
    import pickle

    from .rollout import NumpyPolicy

    with open(stats, "rb") as f:
        norm: VecNormalize = pickle.load(f)
    norm.training = False
    low, high = saved.action_space.low, saved.action_space.high
    fast = NumpyPolicy(saved) if NumpyPolicy.supports(saved) else None

    def act(obs: np.ndarray) -> np.ndarray:
        if fast is not None:  # the Gaussian's mean, as SB3's deterministic predict, without torch
            return np.clip(fast.mean(norm.normalize_obs(obs)), low, high).astype(np.float32)
        action, _ = saved.predict(norm.normalize_obs(obs), deterministic=True)
        return action

    return act
