"""What a building spec declares, as plain frozen dataclasses (`load_spec` in spec.py builds them from a file)."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from parallel_eplus.buildings.clock import WEEKDAYS  # noqa: F401  (the spec's day names; re-exported)
from parallel_eplus.buildings.weather.forecast_features import ForecastSpec

REWARD_KEYS = ("center", "lower", "upper", "gaussian_weight", "band_weight", "power_weight")
OBJECTIVES = ("energy", "hvac", "cost", "emissions")  # what the reward's energy term counts (buildings/scoring/kpis.py)
THERMOSTAT = "thermostat"  # `band = "thermostat"`: each zone's bounds are its own setpoint schedules' values
THERMOSTAT_TOLERANCE = 0.2  # K: the default `reward.tolerance` with thermostat bounds (docs/kpis.md)
OCCUPANCY_OBSERVATION = "occupancy"  # the observation `occupied = { schedule = ... }` adds


class SpecError(ValueError):
    """Every problem found in one spec file, one per line."""


VENTILATION = ("own", "demand")  # the controller's copy: its outdoor air as the model has it, or on demand


@dataclass(frozen=True)
class Observation:
    """One element of the observation vector: an output variable (with its key) or a meter, and its bounds."""

    name: str
    low: float
    high: float
    variable: str | None = None
    key: str | None = None
    meter: str | None = None
    unit: str = ""
    scale: float = 1.0


@dataclass(frozen=True)
class ActuatorSpec:
    """One EnergyPlus actuator, named as `list_available_api_data_csv` lists it (component, control, key)."""

    component: str
    control: str
    key: str


# Where the building's own controls' choice for an actuator can be read back (an output variable on the same key),
# for `train --init-from-baseline`; other actuators need `readback = { variable = ..., key = ... }` in the spec.
READBACKS = {
    ("system node setpoint", "temperature setpoint"): "System Node Setpoint Temperature",
    ("fan", "fan air mass flow rate"): "Fan Air Mass Flow Rate",
    ("zone temperature control", "cooling setpoint"): "Zone Thermostat Cooling Setpoint Temperature",
    ("zone temperature control", "heating setpoint"): "Zone Thermostat Heating Setpoint Temperature",
}


@dataclass(frozen=True)
class ActionSpec:
    """One element of the action: scaled from [-1, 1] to [low, high] and written to every actuator listed."""

    name: str
    low: float
    high: float
    initial: float
    actuators: tuple[ActuatorSpec, ...]
    unit: str = ""
    readback_named: tuple[str, str] | None = None  # (variable, key) the spec names

    @property
    def readback(self) -> tuple[str, str] | None:
        """(variable, key): what the building's own controls set this action's first actuator to, as an output
        variable; the spec's own, else inferred from the actuator's kind (`READBACKS`); None: unknown."""
        if self.readback_named:
            return self.readback_named
        a = self.actuators[0] if self.actuators else None
        variable = READBACKS.get((a.component.lower(), a.control.lower())) if a else None
        return (variable, a.key) if variable else None


@dataclass(frozen=True)
class Occupancy:
    """When the comfort band applies: where an observation (an EnergyPlus schedule's value, read each step) is
    above `above`, or by the clock (hours [start, end) on `weekdays`, 0 = Monday). Elsewhere samples count for
    energy only."""

    observation: str | None = None
    above: float = 0.0
    hours: tuple[float, float] | None = None
    weekdays: tuple[int, ...] = tuple(range(7))


@dataclass(frozen=True)
class RewardSpec:
    """The paper's reward over any zones: which observations are temperatures, power and energy, and the band."""

    temperatures: tuple[str, ...]
    power: str
    band: tuple[float, float]
    params: dict[str, float] = field(default_factory=dict)  # optional RewardConfig overrides
    # Observations (W) summed for the reward's energy term and the energy figure: every fuel the model meters.
    # Empty: `power` alone (electricity).
    energy: tuple[str, ...] = ()
    occupied: Occupancy | None = None  # None: the band applies at every step
    # Per zone (in `temperatures` order): a fixed band each, or None: `band` for every zone. With `thermostat`
    # each zone's bounds are read each step from its thermostat's schedules (buildings/idf/thermostat.py).
    zone_bands: tuple[tuple[float, float], ...] | None = None
    thermostat: bool = False
    objective: str = "energy"  # what the reward's energy term and the comfort constraint trade against
    # K a sample may lie outside its bounds and still count in the share in band (not in discomfort, K·h): a
    # thermostat holds its setpoint to a few hundredths of a kelvin, not exactly (docs/kpis.md)
    tolerance: float = 0.0

    @property
    def energy_terms(self) -> tuple[str, ...]:
        return self.energy or (self.power,)


@dataclass(frozen=True)
class KpiSpec:
    """`[kpis]`: how BOPTEST's figures are counted (buildings/scoring/kpis.py). Fuels are EnergyPlus's resource names.

    `hvac`: fuel -> an observation name, or a meter or output variable read for the figures only (not observed);
    empty: electricity from `Facility Total HVAC Electricity Demand Rate`. `tariff`: fuel -> a constant price per
    kWh, {day, night, day_hours} or {csv} (a price series, read at the episode's end). `emissions`: fuel -> kg
    CO2e per kWh. `floor_area_m2`: None takes it from the model (its zones as EnergyPlus reports them)."""

    hvac: tuple[tuple[str, str], ...] = ()
    tariff: tuple[tuple[str, Any], ...] = ()
    emissions: tuple[tuple[str, float], ...] = ()
    floor_area_m2: float | None = None


@dataclass(frozen=True)
class BuildingSpec:
    """One controllable building, as loaded and validated from its TOML file (paths resolved)."""

    name: str
    path: Path
    idf: Path
    observations: tuple[Observation, ...]
    actions: tuple[ActionSpec, ...]
    reward: RewardSpec
    weathers: dict[str, Path] = field(default_factory=dict)
    controller: str | None = None
    time_features: bool = False
    schedule_features: bool = False
    timesteps_per_hour: int | None = None  # None: the IDF's Timestep
    baseline_idf: Path | None = None  # the model with its own controls, for evaluation; None: `idf` itself
    kpis: KpiSpec = field(default_factory=lambda: KpiSpec())  # `[kpis]`: HVAC energy, tariff, emissions
    # Observations that are forecasts of the episode's weather file (`forecast = "drybulb"` entries), computed on
    # the learner's side after the sensors and the opt-in features (buildings/weather/forecast_features.py).
    forecasts: tuple[ForecastSpec, ...] = ()
    # "demand": the controller's copy of the model takes its outdoor air on demand (buildings/idf/ventilation.py);
    # "own": as the model has it
    ventilation: str = "own"
    # `controller_settings`: the spec's `controller`'s settings (its config's fields: buildings/rules/settings.py)
    controller_settings: tuple[tuple[str, Any], ...] = ()
    # `preset`: the shipped preset `train --building` trains when no algorithm or preset is named (default: its
    # kind's, from the band: parallel_eplus/presets/catalog.py `default_for`)
    preset: str | None = None

    @property
    def demand_ventilation(self) -> bool:
        """Whether the controller's copy takes its outdoor air on demand (buildings/idf/ventilation.py)."""
        return self.ventilation == "demand"
