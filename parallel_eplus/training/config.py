"""A training run's settings: plain data classes, saved as runs/<name>/config.json."""

from __future__ import annotations

import json
import math
import os
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

from parallel_eplus.buildings.datacenter import STEPS_PER_DAY
from parallel_eplus.buildings.scoring.reward import RewardConfig
from parallel_eplus.buildings.weather.files import parse_weathers
from parallel_eplus.engine.config import RESIDUAL_SPACES
from parallel_eplus.learning.model_based.settings import MBPOSettings, MPCSettings
from parallel_eplus.learning.settings import (
    ComfortConstraint,
    ImitationSettings,
    PPOSettings,
    SACSettings,
    TRPOSettings,
)
from parallel_eplus.training.eval_target import EvalSettings

if TYPE_CHECKING:
    from parallel_eplus.buildings.building import Building

STEPS_PER_YEAR = 365 * STEPS_PER_DAY


@dataclass
class TrainConfig:
    """Everything a training run needs; saved as runs/<name>/config.json."""

    workers: int = field(default_factory=lambda: os.cpu_count() or 1)
    weathers: list[str] = field(default_factory=lambda: ["CA"])
    model: str = "temp_fan"
    building: str | None = None  # a building spec (TOML); None: the data center (`model` picks its variant)
    timesteps: int = 1_000_000
    run_days: int = 365
    random_start: bool = False  # each episode from a day of the year drawn for it (every season), not January 1
    prepare_next: bool = True  # each worker prepares its next episode while one runs (engine/episodes/prepared.py)
    fork_episodes: bool = True  # ...forked from an EnergyPlus parked at its first step (engine/episodes/fork.py)
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
    step_timeout_s: float = 60.0  # a worker silent this long is hung: its episode restarts (SimulationConfig)
    # True: every worker waits for the slowest at each step (SB3's way; a seed fixes the run bit for bit).
    # False: each local worker gets its next action as soon as its observation arrives (rollout.py).
    lockstep: bool = False
    # True (TRPO, PPO): the workers collect batch k+1 with the policy before the update on batch k, while the
    # learner runs that update; each update then learns from data one policy old (learning/overlap.py).
    overlap: bool = False
    time_features: bool = False  # opt-in hour/weekday observation features (model.TIME_FEATURES)
    schedule_features: bool = False  # opt-in IT-load schedule features (model.SCHEDULE_FEATURES)
    # a saved model.zip whose weights and observation statistics start this run (mbpo: a planner run's folder)
    init_from: str | None = None
    algorithm: str = "trpo"  # the paper's; or "ppo", "sac", "mpc", "mbpo"
    preset: str | None = None  # the shipped preset its settings started from (`--preset`; parallel_eplus/presets/)
    residual_scale: float = 0.0  # > 0: the policy corrects the rule-based controller (SimulationConfig)
    residual_space: str = "action"  # what it corrects: each action, or each zone's flow demand (SimulationConfig)
    rbc_target_c: float | None = None  # that controller's zone target; None: RBCConfig's
    reward: RewardConfig = field(default_factory=RewardConfig)
    comfort: ComfortConstraint = field(default_factory=ComfortConstraint)  # --comfort-target (learning/lagrangian.py)
    objective: str | None = None  # --objective: energy, hvac, cost, emissions (scoring/kpis.py); None: the spec's
    # Weather noise per episode (buildings/weather/noise.py's form, "drybulb=1:0:24"; None: the files as they are)
    # and the outdoor dry bulb's next `forecast_hours` as observations, with BOPTEST's `forecast_error` level.
    weather_noise: str | None = None
    forecast_hours: int = 0
    forecast_error: str | None = None
    init_from_baseline: bool = False  # imitate the building's own controls first (learning/imitation.py)
    imitation: ImitationSettings = field(default_factory=ImitationSettings)
    trpo: TRPOSettings = field(default_factory=TRPOSettings)
    ppo: PPOSettings = field(default_factory=PPOSettings)
    sac: SACSettings = field(default_factory=SACSettings)
    evaluation: EvalSettings = field(default_factory=EvalSettings)  # --eval-every (training/periodic_eval.py)
    mpc: MPCSettings = field(default_factory=MPCSettings)  # `--algorithm mpc` (learning/model_based/)
    mbpo: MBPOSettings = field(default_factory=MBPOSettings)  # `--algorithm mbpo` (mbpo/algorithm.py)

    def resolved(self, building: Building | None = None) -> TrainConfig:
        """Validate, and fill in the run name. `building`: `self.building` as the caller resolved it (None: resolved
        here)."""
        if self.building:
            from parallel_eplus.buildings.check.names import check_building
            from parallel_eplus.buildings.resources import builtin_specs
            from parallel_eplus.buildings.scoring.reward import reward_config

            spec = check_building(building or self.building)  # a path, or a built-in spec's name
            # A built-in spec is saved by name: the run's config.json then works from another checkout, an
            # install, or a Ray node (whose package sits elsewhere).
            builtin = builtin_specs().get(spec.path.stem)
            same = builtin is not None and builtin.resolve() == spec.path.resolve()
            self.building = spec.path.stem if same else str(spec.path)
            known = spec.weathers
            if self.reward == RewardConfig():  # the spec's reward unless the user gave constants
                self.reward = reward_config(spec)
            self.time_features |= spec.time_features  # the spec's opt-in observation features
            self.schedule_features |= spec.schedule_features
        parse_weathers(",".join(self.weathers), known if self.building else None)
        if self.evaluation.weathers:
            parse_weathers(",".join(self.evaluation.weathers), known if self.building else None)
        if self.workers < 1:
            raise ValueError("--workers must be at least 1")
        if self.batch_size < self.workers:
            raise ValueError("--batch-size must be at least the number of workers")
        if not 1 <= self.run_days <= 365:
            raise ValueError(f"--run-days must be within 1..365 (episodes run within the year), got {self.run_days}")
        if self.timesteps < 0 or self.checkpoint_every < 1:
            raise ValueError("--timesteps must be >= 0 and --checkpoint-every >= 1")
        if self.init_from is not None:
            self.init_from = str(Path(self.init_from).resolve())
        if self.algorithm not in ("trpo", "ppo", "sac", "mpc", "mbpo"):
            raise ValueError(f"unknown algorithm {self.algorithm!r}: use trpo, ppo, sac, mpc or mbpo")
        if self.algorithm == "mbpo":
            self._check_mbpo()
        if self.algorithm == "mpc" and (self.overlap or self.init_from or self.residual_scale):
            raise ValueError("--algorithm mpc plans on a model it learns: no --overlap, --init-from or --residual")
        if self.mpc.comfort_level == "baseline" and (not self.constrained or self.mpc.comfort_weight is not None):
            raise ValueError("--mpc comfort_level=baseline sets the share in band the multiplier holds: give "
                             "--comfort-target PCT and no fixed comfort_weight")  # fmt: skip
        if self.residual_scale < 0 or (self.residual_scale and self.model != "temp_fan"):
            raise ValueError("--residual needs a scale >= 0 and --model temp_fan (it corrects all four actions)")
        if self.residual_space not in RESIDUAL_SPACES:
            raise ValueError(f"unknown --residual-space {self.residual_space!r}: use {' or '.join(RESIDUAL_SPACES)}")
        if self.residual_space != "action" and not self.residual_scale:
            raise ValueError(f"--residual-space {self.residual_space} needs --residual SCALE")
        self.comfort.check()
        self.evaluation.check(self.weathers)
        from parallel_eplus.buildings.weather.forecast_features import ERROR_LEVELS
        from parallel_eplus.buildings.weather.noise import parse_noise

        parse_noise(self.weather_noise)
        if self.forecast_hours < 0 or (self.forecast_error is not None and self.forecast_error not in ERROR_LEVELS):
            raise ValueError(f"--forecast takes hours >= 0 and --forecast-error one of {', '.join(ERROR_LEVELS)}")
        if self.forecast_error is not None and not self.forecast_hours:
            raise ValueError("--forecast-error needs --forecast N (the hours of outdoor temperature forecast)")
        if self.init_from_baseline and self.init_from is not None:
            raise ValueError("--init-from-baseline and --init-from both give the first policy: pass one of them")
        if self.init_from_baseline and self.residual_scale:
            raise ValueError("--init-from-baseline imitates the building's own controls; --residual corrects ours")
        if self.backend not in ("local", "ray"):
            raise ValueError(f"unknown backend {self.backend!r}: use local or ray")
        if self.overlap and (self.off_policy or self.lockstep):
            raise ValueError("--overlap is for TRPO and PPO without --lockstep (SAC updates as it steps; lockstep "
                             "steps every worker from the learner)")  # fmt: skip
        if self.run_name is None:
            self.run_name = f"{self.algorithm}-{'-'.join(self.weathers)}-{time.strftime('%Y%m%d-%H%M%S')}"
        # Absolute, so a resumed run writes to the same places from any working directory.
        self.runs_dir = str(Path(self.runs_dir).resolve())
        self.tensorboard_dir = str(Path(self.tensorboard_dir).resolve())
        return self

    def check_new_run(self) -> None:
        """What only a new run must satisfy (a resumed run keeps its saved settings)."""
        if not self.off_policy and self.batch_size % self.workers:
            b, w = self.batch_size, self.workers
            raise ValueError(
                f"--batch-size {b} does not split evenly across {w} workers: use {b - b % w} or {b + w - b % w}"
            )

    @property
    def run_dir(self) -> Path:
        """Where this run's model, checkpoints, config and episode records go."""
        return Path(self.runs_dir) / str(self.run_name)

    def continue_in(self, run_dir: Path) -> None:
        """Continue the run in `run_dir`, where its files are now: a run folder copied or moved (another machine, a
        committed result restored) resumes there, not in the folder it was made in. Its TensorBoard logs move with
        it when they sat beside its runs folder (the default layout)."""
        run_dir = Path(run_dir).absolute()
        if run_dir == self.run_dir.absolute():
            return
        home, logs = Path(self.runs_dir).absolute().parent, Path(self.tensorboard_dir).absolute()
        if logs.is_relative_to(home):
            self.tensorboard_dir = str(run_dir.parent.parent / logs.relative_to(home))
        self.runs_dir, self.run_name = str(run_dir.parent), run_dir.name

    def _check_mbpo(self) -> None:
        if not self.constrained:
            raise ValueError("--algorithm mbpo keeps comfort as a constraint: give --comfort-target PCT (e.g. 99.6)")
        if self.residual_scale or self.init_from_baseline or self.forecast_hours:
            raise ValueError("--algorithm mbpo: no --residual, --init-from-baseline or --forecast (a forecast in the "
                             "observation cannot be rebuilt along the model's rollouts)")  # fmt: skip
        if self.mbpo.rollout_length > self.mpc.horizon:
            raise ValueError(f"--mbpo rollout_length {self.mbpo.rollout_length}: at most --mpc horizon "
                             f"({self.mpc.horizon})")  # fmt: skip

    @property
    def off_policy(self) -> bool:
        """SAC's learners: a replay buffer, updates as they step (no batches)."""
        return self.algorithm in ("sac", "mbpo")

    @property
    def constrained(self) -> bool:
        """Comfort as a constraint (`--comfort-target`) rather than the reward's fixed weights."""
        return self.comfort.target_pct is not None

    @property
    def n_steps(self) -> int:
        """Steps per worker per batch."""
        return math.ceil(self.batch_size / self.workers)

    def to_json(self) -> str:
        """The run's settings as saved in its config.json."""
        return json.dumps(asdict(self), indent=2)

    @classmethod
    def from_json(cls, text: str) -> TrainConfig:
        """A run's settings from its config.json (what `--resume` reads)."""
        raw = json.loads(text)
        raw["reward"] = RewardConfig(**raw["reward"])
        raw["trpo"] = TRPOSettings(**{**raw["trpo"], "net_arch": tuple(raw["trpo"]["net_arch"])})
        raw["ppo"] = PPOSettings(**raw.get("ppo", {}))  # runs from before PPO have none
        raw["comfort"] = ComfortConstraint(**raw.get("comfort", {}))  # runs from before it have none
        raw["imitation"] = ImitationSettings(**raw.get("imitation", {}))
        sac = raw.get("sac", {})
        raw["mpc"] = MPCSettings.of_saved(raw.get("mpc", {}), "a run's config.json")  # 1.0's names renamed
        raw["mbpo"] = MBPOSettings(**raw.get("mbpo", {}))
        raw["sac"] = SACSettings(**{**sac, "net_arch": tuple(sac.get("net_arch", SACSettings.net_arch))})
        raw["evaluation"] = EvalSettings(**raw.get("evaluation", {}))  # runs from before it have none
        return cls(**raw)


__all__ = [
    "STEPS_PER_YEAR",
    "ComfortConstraint",
    "ImitationSettings",
    "PPOSettings",
    "SACSettings",
    "TRPOSettings",
    "TrainConfig",
]
