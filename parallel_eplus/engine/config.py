"""What one EnergyPlus worker simulates: plain data, so it can be logged, saved and sent to Ray actors."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING

from parallel_eplus.buildings.datacenter import (
    control_model,
)
from parallel_eplus.buildings.rules.datacenter import DEMAND_CORRECTIONS
from parallel_eplus.buildings.scoring.reward import RewardConfig

if TYPE_CHECKING:
    from parallel_eplus.buildings.building import Building


@dataclass
class SimulationConfig:
    """What one worker simulates; plain data, so it can be logged, saved and sent to Ray actors."""

    weather: str = "CA"  # code or .epw path; a list cycles episode by episode
    model: str = "temp_fan"
    # A building spec (TOML, buildings/spec/load.py): its IDF, sensors, actions and reward signals replace the
    # data center's and `model`'s. None: the data center (buildings/specs/datacenter-2zone.toml).
    building: str | None = None
    run_days: int = 365
    output_dir: str | None = None  # None: a temporary directory removed on close
    keep_episodes: int | None = None  # this env's newest full episode directories kept; None keeps all
    # EnergyPlus's own eplusout.csv in each episode (where the model asks for one): training turns it off,
    # its cost being memory and time (buildings/idf/prepare.py), its content ours in steps.parquet.
    energyplus_csv: bool = True
    reward: RewardConfig = field(default_factory=RewardConfig)
    start_timeout_s: float = 180.0  # sizing and warmup come before the first observation
    step_timeout_s: float = 60.0
    idf: str | None = None  # override the model's IDF (same sensors and actuators)
    initial_action: tuple[float, ...] | None = None  # physical units; default: the model's
    spin_s: float | None = None  # busy-wait before blocking on a pipe; None: see spin.default_spin_s
    time_features: bool = False  # append model.TIME_FEATURES to the observation
    schedule_features: bool = False  # then model.SCHEDULE_FEATURES (the IT-load schedule in the IDF)
    # > 0: the action, times this, corrects the rule-based controller's (rbc.py) instead of acting
    # alone (residual control: learning starts from the hand-tuned loop, not from scratch).
    residual_scale: float = 0.0
    # "action": the correction adds to each of the four normalized actions; "demand": one correction
    # per zone, in kg/s, to the controller's split-range flow demand (rbc.DEMAND_CORRECTIONS); "builtin" (a spec
    # building): each action corrects the building's own choice, its thermostat's setpoint schedule, by up to
    # `residual_scale` of half the action's range, added on EnergyPlus's side at the step it applies to (bridge.py),
    # so a zero correction runs the building's own controls exactly.
    residual_space: str = "action"
    rbc_target_c: float | None = None  # that controller's zone target; None: RBCConfig's
    # Envs and vector envs: fork each episode's process from a warm interpreter and start the next episode while
    # one runs, so a reset finds it parked at its first step (episodes/prepared.py). A lone Simulation never does.
    prepare_next: bool = True
    # With prepare_next: episodes forked from an EnergyPlus parked at the run period's first control step, one per
    # weather file, so input processing, sizing and warm-up are paid once, not per episode (episodes/fork.py). Not
    # with weather noise (a new weather file each episode): those start as without it.
    fork_episodes: bool = True
    native_bridge: bool = True  # EnergyPlus's side of each step in C (native.py) where a C compiler works
    # Set: comfort is a constraint (learning/lagrangian.py): the reward pays for energy only and each step reports
    # a comfort cost rising over this many kelvin inside the band's edges, and its zones out of band.
    comfort_margin_c: float | None = None
    # Read-back output variables (key, variable) added to the model's EnergyPlus CSV, every timestep: what the
    # building's own controls chose, for `train --init-from-baseline` (learning/imitation.py).
    extra_outputs: tuple[tuple[str, str], ...] = ()
    # What the reward's energy term counts (energy, hvac, cost, emissions; buildings/scoring/kpis.py). None: the spec's.
    objective: str | None = None
    # A test period (evaluation/scenarios.py): the run starts on this day of the year, on this weekday (None: the
    # model's own), and its first `warmup_days` are simulated but left out of the episode's figures.
    start_day: int = 1
    start_weekday: str | None = None
    warmup_days: int = 0
    # Training across the seasons (BOPTEST-Gym's random start time): each episode starts on a day of the year drawn
    # for it (fixed by the seed, the worker and the episode's number), `run_days` long within the year.
    random_start: bool = False
    # Weather that varies per episode (buildings/weather/noise.py's `parse_noise` form, e.g. "drybulb=1:0:24"):
    # each episode runs a perturbed copy of its EPW, written into its folder. None: the file as it is.
    weather_noise: str | None = None
    # Seeds each episode's noise and forecast error with (seed, worker, episode number); `reset(seed=)` sets one.
    seed: int = 0
    fixed_seed: bool = False  # every episode's seed is `seed` itself (evaluate's noisy year N: the same for all)
    forecast_hours: int = 0  # > 0: the outdoor dry bulb's next N hours end the observation (weather/forecast_features)
    forecast_error: str | None = None  # BOPTEST's "low", "medium" or "high" error on that forecast; None: exact
    # The model's own controls under the actions (the BACnet device, deploy/bacnet/device.py): the building's
    # `baseline_idf` runs with the actions' actuators, and an action element that is NaN releases them to its own
    # setpoint managers and fan controls for that step. `initial_action` NaN: warm-up under its own controls too.
    relinquish: bool = False
    # The oracle's (issue 89): the episode serves forks of itself wherever it awaits an action, each playing given
    # actions over a horizon (engine/eplus_side/branch.py; our side engine/episodes/branch.py). Python bridge only.
    branching: bool = False


RESIDUAL_SPACES = ("action", "demand", "builtin")


def forecast_specs(config: SimulationConfig, building: Building | None = None):
    """The forecasts ending the observation: the building spec's own, then `forecast_hours`' outdoor one.
    `building`: the config's, resolved already (None: resolved here)."""
    from parallel_eplus.buildings.building import load_building
    from parallel_eplus.buildings.weather.forecast_features import outdoor_forecast

    extra = (outdoor_forecast(config.forecast_hours, config.forecast_error),) if config.forecast_hours else ()
    return (building or load_building(config.building)).spec.forecasts + extra


def policy_action_names(config: SimulationConfig, building: Building | None = None) -> tuple[str, ...]:
    """The elements of the action a policy gives: the model's own, or per-zone demand corrections. `building`: the
    config's, resolved already (None: resolved here)."""
    if config.residual_space not in RESIDUAL_SPACES:
        raise ValueError(f"unknown residual space {config.residual_space!r}: use {' or '.join(RESIDUAL_SPACES)}")
    if config.residual_scale and config.residual_space == "demand":
        return DEMAND_CORRECTIONS
    if config.building and config.model != "baseline":
        from parallel_eplus.buildings.building import load_building

        return tuple(e.name for e in (building or load_building(config.building)).actions)
    return tuple(e.name for e in control_model(config.model).actions)
