"""What every episode of one worker shares, resolved once from its config and building before anything is spawned.

The model variant and its IDF, the sensors and their bounds, the comfort signals under the run's objective, the
action elements and their bounds, the weathers, the weather noise and forecasts: each checked here, so a bad option
fails in the learner with a clear message rather than in a worker's EnergyPlus process.
"""

from __future__ import annotations

import dataclasses
import zlib
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from parallel_eplus.buildings.building import Building, load_building
from parallel_eplus.buildings.datacenter import ACTIONS, ActionElement, ControlModel, control_model, it_load_schedule
from parallel_eplus.buildings.rules.datacenter import RBCConfig, RuleBasedController
from parallel_eplus.buildings.scoring.comfort import Comfort
from parallel_eplus.buildings.spec.load import OBJECTIVES
from parallel_eplus.buildings.weather.files import resolve_weather
from parallel_eplus.buildings.weather.forecast_features import Forecaster, ForecastSpec
from parallel_eplus.buildings.weather.noise import parse_noise, perturb_epw
from parallel_eplus.engine.config import SimulationConfig, forecast_specs, policy_action_names
from parallel_eplus.engine.episode import EpisodePlan, link_or_copy

if TYPE_CHECKING:  # the EnergyPlus side imports no pandas (tests/test_packaging.py)
    import pandas as pd


@dataclass(frozen=True)
class WorkerSetup:
    """One worker's fixed facts (`resolve` checks them); `Simulation` reads its hot-path ones as attributes."""

    config: SimulationConfig
    building: Building
    model: ControlModel
    comfort: Comfort  # zones, band, when it applies, energy under the run's objective (buildings/scoring/comfort.py)
    idf: Path
    obs_low: np.ndarray  # float32
    obs_high: np.ndarray
    observed: int  # the sensors after these are read for the figures only (thermostat schedules, HVAC meters)
    schedule: object | None  # the IT-load schedule, for the schedule features
    noise: object | None  # the weather noise (buildings/weather/noise.py)
    forecasts: tuple[ForecastSpec, ...]
    weathers: list[str]
    weather_paths: list[Path]
    steps_per_episode: int
    initial_action: np.ndarray  # physical units
    policy_names: tuple[str, ...]  # what `Simulation.send` takes; `action_names`: what EnergyPlus gets

    @property
    def elements(self) -> tuple[ActionElement, ...]:
        return self.model.actions

    def process_args(self) -> list[str]:
        """The EnergyPlus-side program's arguments that every episode of this worker shares."""
        building = ["--building", str(self.building.spec.path)] if self.config.building else []
        own = ["--builtin-residual"] if self.builtin_residual else []
        own += ["--relinquish"] if self.config.relinquish else []
        own += ["--branching"] if self.config.branching else []
        return ["--model", self.model.name, *building, "--steps", str(self.steps_per_episode),
                "--initial-action", *map(str, self.initial_action), *own]  # fmt: skip

    @property
    def demand_ventilation(self) -> bool:
        """Whether this worker's copy takes its outdoor air on demand: the spec's `ventilation = "demand"`, for
        its controllers, never its own controls (`--baseline`), which run the model as it is."""
        return self.building.spec.demand_ventilation and self.model.name != "baseline"

    @property
    def builtin_residual(self) -> bool:
        """Whether actions are corrections to the building's own setpoint schedules (`residual_space` builtin)."""
        return bool(self.config.residual_scale) and self.config.residual_space == "builtin"

    def residual_base(self) -> RuleBasedController | None:
        """With `residual_scale`, the rule-based controller a residual action corrects (one per episode: it keeps an
        integral state); its feed-forward reads the IT schedule of the model actually run, as the schedule features
        do. None without."""
        if not self.config.residual_scale or self.builtin_residual:
            return None
        target = self.config.rbc_target_c
        rbc = {"schedule": it_load_schedule(self.idf)} | ({} if target is None else {"target_c": target})
        return RuleBasedController(RBCConfig(**rbc))

    def scored_steps(self, steps: pd.DataFrame, extra: dict) -> pd.DataFrame | None:
        """The steps an episode's figures count (a test period leaves out its warm-up; None: all), adding to `extra`
        (its summary's fields) the model, run length, building and period."""
        config = self.config
        extra |= {"model": self.model.name, "run_days": config.run_days}
        if config.building:  # what `plot` reads the episode's signals from (none: the data center)
            extra["building"] = str(self.building.spec.path)
        if not config.warmup_days:
            return None
        scored = steps.iloc[config.warmup_days * self.building.steps_per_day :]
        if len(scored):
            extra |= {"warmup_days": config.warmup_days, "period_start": str(scored["time"].iloc[0]),
                      "period_end": str(scored["time"].iloc[-1])}  # fmt: skip
        return scored

    @classmethod
    def resolve(
        cls, config: SimulationConfig, weathers: list[str] | None = None, building: Building | None = None
    ) -> WorkerSetup:
        """`building`: the config's, as the command running it resolved it (None: resolved here from the config's
        spec; None there: the data center, whose variants `model` names)."""
        building = building or load_building(config.building)
        model = building.control(config.model) if config.building else control_model(config.model)
        comfort = building.comfort
        if config.objective and config.objective != comfort.objective:
            if config.objective not in OBJECTIVES:
                raise ValueError(f"objective {config.objective!r} is not one of {list(OBJECTIVES)}")
            if comfort.kpis is None and config.objective != "energy":
                raise ValueError(f"objective {config.objective!r} needs the building's HVAC signals ([kpis] hvac)")
            comfort = dataclasses.replace(comfort, objective=config.objective)
        idf = Path(config.idf) if config.idf else model.idf
        if config.relinquish and not config.idf:  # the model with its own controls, under the actions' actuators
            if config.residual_scale or config.model == "baseline":
                raise ValueError("relinquish runs the building's own controls under plain actions: no residual")
            idf = (building.control("baseline") if config.building else control_model("baseline")).idf
        if not idf.is_file():
            raise FileNotFoundError(f"model file not found: {idf}")
        weathers = weathers or [config.weather]
        named = building.spec.weathers  # the spec's short names, then codes and .epw paths
        if config.warmup_days >= config.run_days and config.warmup_days:
            raise ValueError(f"warmup_days ({config.warmup_days}) must be fewer than run_days ({config.run_days})")
        if config.random_start and (config.start_day != 1 or config.warmup_days):
            raise ValueError("random_start draws each episode's first day: leave start_day and warmup_days unset")
        elements = model.actions
        initial = np.array(config.initial_action or [e.initial for e in elements], float)
        if len(initial) != len(elements):
            raise ValueError(f"initial_action needs {len(elements)} values in physical units")
        if config.residual_scale < 0:
            raise ValueError("residual_scale must be >= 0")
        if config.residual_scale and config.residual_space == "builtin":
            _check_builtin_residual(config, building)
        elif config.residual_scale and elements != ACTIONS:
            raise ValueError(f"residual control corrects all four actions; model {config.model!r} has {len(elements)}")
        low, high = (np.array(b, dtype=np.float32) for b in building.bounds())
        return cls(
            config, building, model, comfort, idf, low, high, len(building.observed),
            it_load_schedule(idf) if config.schedule_features else None,
            parse_noise(config.weather_noise),  # a malformed option fails before anything is spawned
            tuple(forecast_specs(config, building)), weathers,
            [named.get(w) or resolve_weather(w) for w in weathers],  # fail before spawning
            config.run_days * building.steps_per_day, initial, tuple(policy_action_names(config, building)),
        )  # fmt: skip

    def start_day(self, worker: str, episode: int) -> int:
        """`random_start`: the first day of the year of this worker's `episode`-th episode, drawn from the config's
        seed, the worker's name and the episode's number, so a prepared episode and a cold one agree; uniform over
        the days whose run of `run_days` ends within the year."""
        rng = np.random.default_rng([self.config.seed, zlib.crc32(worker.encode()), episode, 0x5EA5])
        return int(rng.integers(1, 365 - self.config.run_days + 2))

    def episode_weather(self, plan: EpisodePlan, episode_dir: Path, number: int, worker: str) -> tuple[Path, tuple]:
        """The episode's weather file in its folder (perturbed with `weather_noise`, else a link to the file), and
        (its seed and noise parameters for its records, its forecasts, which read that same file).

        The seed: the plan's, else the config's with `fixed_seed`, else drawn from the config's seed, the worker's
        name and the episode's number (the same episode gets the same year however it was started)."""
        seed, config = plan.seed, self.config
        if seed is None and config.fixed_seed:
            seed = config.seed
        if seed is None:
            seed = int(np.random.SeedSequence([config.seed, zlib.crc32(worker.encode()), number])
                       .generate_state(1)[0])  # fmt: skip
        target = episode_dir / plan.epw.name
        if self.noise is None:
            link_or_copy(plan.epw, target)
            params = {}
        else:
            params = {"weather_seed": seed, **perturb_epw(plan.epw, target, self.noise, seed)}
        if self.forecasts and any(f.error for f in self.forecasts):
            params.setdefault("weather_seed", seed)
        per_hour, days = self.building.steps_per_day // 24, config.run_days
        start = config.start_day if plan.start_day is None else plan.start_day
        forecaster = Forecaster(self.forecasts, target, days, per_hour, seed, start) if self.forecasts else None
        return target, (params, forecaster)


def _check_builtin_residual(config: SimulationConfig, building: Building) -> None:
    """`residual_space` builtin needs a spec building whose every actuator has a schedule of its own to correct."""
    if not config.building or config.model == "baseline":
        raise ValueError("--residual-space builtin corrects a spec building's own setpoint schedules: pass --building")
    lacking = [
        f"{e.name} ({a.component_type}/{a.control_type} on {a.key})"
        for e, own in zip(building.actions, building.own, strict=True)
        for a, name in zip(e.actuators, own, strict=True)
        if name is None
    ]
    if lacking:
        raise ValueError(
            f"--residual-space builtin: {', '.join(lacking)} has no setpoint schedule of the building's own to correct "
            "(a zone thermostat's heating and cooling setpoints have one, and a node a SetpointManager:Scheduled "
            "sets); use --residual-space action with the rule-based controller, or no --residual"
        )
