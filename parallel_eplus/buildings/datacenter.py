"""The data-center model as the package's older modules see it: a thin layer over its building spec.

The facts (sensors, actuators, bounds, reward band) live once, in specs/datacenter-2zone.toml; this module
turns them into the names the env, the EnergyPlus-side callback and the rule-based controller import.
"""

from __future__ import annotations

import functools
import re
from dataclasses import dataclass
from pathlib import Path

from parallel_eplus.buildings.clock import SCHEDULE_FEATURES, TIME_FEATURES, schedule_features, time_features  # noqa: F401
from parallel_eplus.buildings.resources import SOURCE_ROOT as ROOT  # noqa: F401 (scripts and tests in a checkout)
from parallel_eplus.buildings.resources import model_file
from parallel_eplus.buildings.spec.load import BuildingSpec, load_spec

BASELINE_IDF = model_file("2ZoneDataCenterHVAC_wEconomizer.idf")
AGENT_IDF = model_file("2ZoneDataCenterHVAC_wEconomizer_agent.idf")

DEFAULT_SPEC = Path(__file__).resolve().parent / "specs" / "datacenter-2zone.toml"
DEFAULT: BuildingSpec = load_spec(DEFAULT_SPEC)  # the data center: sensors, actuators, bounds, reward band

TIMESTEPS_PER_HOUR = 4  # the model's Timestep object: one control step is 15 minutes
STEPS_PER_DAY = 24 * TIMESTEPS_PER_HOUR
ZONES = ("West", "East")

# Zone temperatures counted as "in range" in the paper's results (Section 5).
COMFORT_BAND_C = DEFAULT.reward.band


@dataclass(frozen=True)
class Sensor:
    """One observation element: an EnergyPlus output variable with the paper's bounds."""

    name: str  # column and `info` key
    variable: str  # EnergyPlus output variable name (or meter name, with `meter`)
    key: str  # EnergyPlus key (zone, node or 'Whole Building')
    low: float
    high: float
    meter: bool = False  # `variable` names a meter: read as its mean rate over the zone timestep (J/s, i.e. W)
    scale: float = 1.0  # the value EnergyPlus gives, times this


@dataclass(frozen=True)
class Actuator:
    """One EnergyPlus actuator; several may share one action element."""

    component_type: str
    control_type: str
    key: str


@dataclass(frozen=True)
class ActionElement:
    """One element of the agent's action, scaled from [-1, 1] to [low, high] physical units."""

    name: str
    unit: str
    low: float
    high: float
    actuators: tuple[Actuator, ...]
    # Held through sizing and warmup until the first action arrives. Without one the agent model's nodes
    # have no setpoints and the zones start far from range; these keep both zones near 23 C at night.
    initial: float


# Observation in the paper's order and units (Section 4.2.1), read from the building spec.
SENSORS: tuple[Sensor, ...] = tuple(
    Sensor(o.name, o.variable or o.meter or "", o.key or "", o.low, o.high) for o in DEFAULT.observations
)
SENSOR_NAMES = tuple(s.name for s in SENSORS)
ZONE_TEMP_NAMES = DEFAULT.reward.temperatures

IT_SCHEDULE = "Data Center CPU Loading Schedule"


@functools.cache
def it_load_schedule(idf: Path = AGENT_IDF, name: str = IT_SCHEDULE) -> tuple[tuple[float, float], ...]:
    """(until hour, load fraction) pairs of the model's ordinary-day IT loading, read from the IDF."""
    text = idf.read_text(encoding="latin-1")
    m = re.search(rf"Schedule:Compact,\s*{re.escape(name)},(.*?);", text, re.S | re.I)
    if not m:
        raise ValueError(f"schedule {name!r} not found in {idf}")
    body = re.sub(r"!.*", "", m.group(1))
    days = body.split("For:")
    ordinary = next(d for d in days if "AllOtherDays" in d or "AllDays" in d)
    pairs = re.findall(r"Until:\s*(\d+):(\d+)\s*,\s*([-\d.]+)", ordinary)
    return tuple((int(h) + int(mi) / 60, float(v)) for h, mi, v in pairs)


def observation_names(with_time: bool = False, with_schedule: bool = False) -> tuple[str, ...]:
    """The observation vector's element names, in order, with the opt-in features."""
    return SENSOR_NAMES + (TIME_FEATURES if with_time else ()) + (SCHEDULE_FEATURES if with_schedule else ())


def observation_bounds(with_time: bool = False, with_schedule: bool = False) -> tuple[list[float], list[float]]:
    """(low, high) of every observation element, as the observation space declares them."""
    extra = len(observation_names(with_time, with_schedule)) - len(SENSORS)
    return [s.low for s in SENSORS] + [-1.0] * extra, [s.high for s in SENSORS] + [1.0] * extra


def action_elements(spec: BuildingSpec) -> tuple[ActionElement, ...]:
    """A spec's actions as the engine's `ActionElement`s."""
    return tuple(
        ActionElement(
            a.name,
            a.unit,
            a.low,
            a.high,
            tuple(Actuator(x.component, x.control, x.key) for x in a.actuators),
            a.initial,
        )
        for a in spec.actions
    )


# Action in the paper's order and ranges (Section 4.2.2), read from the building spec.
ACTIONS: tuple[ActionElement, ...] = action_elements(DEFAULT)


@dataclass(frozen=True)
class ControlModel:
    """A building variant and the part of the action the agent owns in it."""

    name: str
    idf: Path
    actions: tuple[ActionElement, ...]


# `temp_fan` controls setpoints and fans; `temp` only setpoints (fans stay on EnergyPlus's VAV control);
# `baseline` is the built-in controller: the stock setpoint managers, no agent action.
MODELS: dict[str, ControlModel] = {
    "temp_fan": ControlModel("temp_fan", AGENT_IDF, ACTIONS),
    "temp": ControlModel("temp", AGENT_IDF, ACTIONS[:2]),
    "baseline": ControlModel("baseline", BASELINE_IDF, ()),
}


def control_model(name: str) -> ControlModel:
    """A control model by name (`temp_fan`, `temp`, `baseline`), or a ValueError listing them."""
    try:
        return MODELS[name]
    except KeyError:
        raise ValueError(f"unknown model {name!r}; choose one of {', '.join(MODELS)}") from None
