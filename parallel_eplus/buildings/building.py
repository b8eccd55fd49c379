"""A loaded building spec as the engine uses it: sensors, action elements, bounds and reward signals.

Both sides of the pipe build one from the same spec file (the env process from `SimulationConfig.building`,
the EnergyPlus side from `--building`), so they agree on every name and order by construction. A command resolves
its building once (`load_building`) and hands the `Building` on: the functions below it that take a spec take the
resolved object too.
"""

from __future__ import annotations

import functools
import importlib
import re
from dataclasses import dataclass
from pathlib import Path

from parallel_eplus.buildings import datacenter
from parallel_eplus.buildings.datacenter import ActionElement, ControlModel, Sensor, action_elements
from parallel_eplus.buildings.idf.takeover import NODE_SETPOINT
from parallel_eplus.buildings.scoring.comfort import Comfort
from parallel_eplus.buildings.spec.load import BuildingSpec, load_spec

# The actuators the zone predictor reads, component types (EnergyPlus's EMS calling point for them:
# BeginTimestepBeforePredictor).
PREDICTOR_ACTUATORS = frozenset({"zone temperature control"})


@dataclass(frozen=True)
class Building:
    """A spec resolved for the engine: its spec read, its model's thermostats and schedules found (`load_building`)."""

    spec: BuildingSpec
    sensors: tuple[Sensor, ...]  # the observations, then the signals read for the figures only (`hidden`)
    actions: tuple[ActionElement, ...]
    hidden: int = 0  # the last `hidden` sensors are not observed: thermostat schedules, HVAC meters
    zone_bounds: tuple[tuple[str, str], ...] | None = None  # per zone: the sensors of its lower and upper bound
    hvac: tuple[tuple[str, str], ...] = ()  # (fuel, sensor in W): HVAC energy, BOPTEST's `ener_tot`
    # Per action, per actuator: the hidden sensor reading the schedule the building's own controls set that
    # actuator to (a thermostat's setpoint schedule), None where there is none; for `--residual-space builtin`.
    own: tuple[tuple[str | None, ...], ...] = ()
    # False: the data center a run gets when it names no building (`load_building(None)`): its configs carry no
    # spec (`SimulationConfig.building` None) and `model` picks its control variant (buildings/datacenter.py)
    named: bool = True

    @functools.cached_property
    def node_schedules(self) -> tuple[tuple[str | None, ...], ...]:
        """Per action, per actuator: the sensor of the schedule a node setpoint's own `SetpointManager:Scheduled`
        follows (`own` on node actuators only), None elsewhere. The prepared copy takes such a node even under
        `relinquish` (episodes/supply.py), and a released one gets the schedule back (eplus_side/bridge.py): one place
        decides which nodes those are."""
        none = tuple((None,) * len(a.actuators) for a in self.actions)
        own = self.own if len(self.own) == len(self.actions) else none
        return tuple(tuple(n if a.component_type.lower() == NODE_SETPOINT else None
                           for a, n in zip(e.actuators, plans, strict=True))
                     for e, plans in zip(self.actions, own, strict=True))  # fmt: skip

    @property
    def observed(self) -> tuple[Sensor, ...]:
        """The sensors the agent observes (the spec's observations)."""
        return self.sensors[: len(self.sensors) - self.hidden]

    def interface(self) -> tuple:
        """What a policy trained on this building reads and sets: its observations and its actions (names, bounds,
        actuators, in order). A spec with the same interface is a variant of the building a policy can act in (its
        model or its copy changed, e.g. `ventilation = "demand"`)."""
        return (tuple((s.name, s.variable, s.key, s.low, s.high) for s in self.observed), self.spec.actions,
                self.spec.time_features, self.spec.schedule_features, self.spec.forecasts)  # fmt: skip

    @property
    def sensor_names(self) -> tuple[str, ...]:
        return tuple(s.name for s in self.sensors)

    @property
    def temperatures(self) -> tuple[str, ...]:
        return self.spec.reward.temperatures

    @property
    def power(self) -> str:
        return self.spec.reward.power

    @property
    def band(self) -> tuple[float, float]:
        return self.spec.reward.band

    @functools.cached_property
    def steps_per_day(self) -> int:
        """Control steps a day: the spec's, else the model's own Timestep (its IDF read once, not every episode)."""
        return 24 * (self.spec.timesteps_per_hour or timesteps_per_hour(self.spec.idf))

    @functools.cached_property
    def before_predictor(self) -> bool:
        """Whether the EnergyPlus side sets the action at BeginTimestepBeforePredictor (`applies_before_predictor`)
        rather than after the HVAC managers (bridge.py)."""
        return applies_before_predictor(self.spec)

    @functools.cached_property
    def comfort(self) -> Comfort:
        """Its reward signals: zones, band, when the band applies, power and energy (buildings/scoring/comfort.py)."""
        return Comfort.of(self.spec, self.steps_per_day // 24, self.zone_bounds, self.hvac)

    def bounds(self) -> tuple[list[float], list[float]]:
        """The observation's bounds (the observed sensors')."""
        return [s.low for s in self.observed], [s.high for s in self.observed]

    def controller_class(self, rule: str | None = None) -> type:
        """The class the spec's `controller = "module:Class"` names, or `rule` (`--rbc module:Class`): its
        rule-based controller."""
        named = rule or self.spec.controller
        if not named:
            raise ValueError(
                f'{self.spec.path}: --rbc needs the spec to name a controller (controller = "module:Class") '
                "or a class after it (--rbc module:Class)"
            )
        module, _, name = named.partition(":")
        try:
            return getattr(importlib.import_module(module), name)
        except (ImportError, AttributeError) as e:
            raise ValueError(f"{self.spec.path}: controller {named!r} cannot be imported: {e}") from None

    def control(self, model: str = "") -> ControlModel:
        """The spec's agent variant (its IDF, all its actions), or with "baseline" its built-in controls."""
        if model == "baseline":
            return ControlModel("baseline", self.spec.baseline_idf or self.spec.idf, ())
        return ControlModel(self.spec.name, self.spec.idf, self.actions)


def applies_before_predictor(spec: BuildingSpec) -> bool:
    """Whether every actuator is one the zone predictor reads (a thermostat's setpoints) or a node setpoint taken
    over from the model's managers (buildings/idf/takeover.py). EnergyPlus's EMS guide sets thermostats before the
    predictor; set after it, as node setpoints and fan flows otherwise are (after the HVAC managers, whose setpoint
    managers would overwrite them), a thermostat setpoint acts a zone timestep late. A node no manager sets any more
    is set before them too, so the managers that follow it (MixedAir: the coils' setpoints) see it in the same
    timestep; after them, the medium office's supply air followed the action one zone timestep late."""
    from parallel_eplus.buildings.idf.prepare import takeover_report
    from parallel_eplus.buildings.idf.takeover import NODE_SETPOINT

    kinds = {a.component.lower() for action in spec.actions for a in action.actuators}
    if not kinds or not kinds <= PREDICTOR_ACTUATORS | {NODE_SETPOINT}:
        return False
    nodes = {a.key.upper() for action in spec.actions for a in action.actuators if a.component.lower() == NODE_SETPOINT}
    if not nodes:
        return True
    return nodes <= {n.upper() for r in takeover_report(spec.idf, spec.actions).replaced for n in r.nodes}


def timesteps_per_hour(idf: Path) -> int:
    """The model's own `Timestep` (zone timesteps per hour; EnergyPlus's default, 6, if it has none)."""
    text = re.sub(r"!.*", "", idf.read_text(encoding="latin-1"))
    m = re.search(r"^[ \t]*Timestep,\s*(\d+)\s*;", text, re.MULTILINE | re.IGNORECASE)
    return int(m.group(1)) if m else 6


@functools.cache
def _load(path: Path, named: bool = True) -> Building:
    spec = datacenter.DEFAULT if path == datacenter.DEFAULT_SPEC else load_spec(path)
    sensors = tuple(
        Sensor(o.name, o.variable or o.meter or "", o.key or "", o.low, o.high, o.meter is not None, o.scale)
        for o in spec.observations
    )
    actions = action_elements(spec)
    model = _model_objects(spec, actions)  # the IDF, parsed once for the thermostats and schedules read below
    hidden: list[Sensor] = []
    bounds = _thermostat_bounds(spec, model, hidden) if spec.reward.thermostat else None
    hvac = _hvac_signals(spec, hidden)
    own = _own_schedules(model, actions, hidden)
    return Building(spec, sensors + tuple(hidden), actions, len(hidden), bounds, hvac, own, named)


def _model_objects(spec: BuildingSpec, actions) -> list:
    """The model's objects (buildings/idf/objects.py) where the building reads its thermostats or its own schedules;
    empty where it reads neither."""
    from parallel_eplus.buildings.idf.objects import idf_objects

    if not (spec.reward.thermostat or any(side for sides in _own_sides(actions) for side in sides)):
        return []
    return idf_objects(spec.idf.read_text(encoding="latin-1"))


HVAC_ELECTRICITY = "Facility Total HVAC Electricity Demand Rate"  # W: every HVAC electric end use, no lights/plugs


def _hidden(hidden: list[Sensor], name: str, variable: str, key: str, meter: bool = False) -> str:
    if all(h.name != name for h in hidden):
        hidden.append(Sensor(name, variable, key, -1e12, 1e12, meter))
    return name


# The actuators whose built-in value is a schedule: a zone thermostat's setpoint schedules (thermostat.py), and a
# node's supply-air temperature where a `SetpointManager:Scheduled` sets it (takeover.py)
_OWN_SIDE = {("zone temperature control", "heating setpoint"): "heating",
             ("zone temperature control", "cooling setpoint"): "cooling",
             ("system node setpoint", "temperature setpoint"): "node"}  # fmt: skip


def _own_sides(actions) -> list[list[str | None]]:
    """Per action, per actuator: which of the model's own schedules it has (`_OWN_SIDE`), None: none."""
    return [[_OWN_SIDE.get((a.component_type.lower(), a.control_type.lower())) for a in e.actuators] for e in actions]


def _own_schedules(model: list, actions, hidden: list[Sensor]) -> tuple[tuple[str | None, ...], ...]:
    """Per action, per actuator: the hidden sensor of the schedule the model's own controls follow there (the
    value the built-in controls would set; read each step, as the thermostat bounds are), None elsewhere.
    `model`: the IDF's objects."""
    from parallel_eplus.buildings.idf.takeover import scheduled_setpoints
    from parallel_eplus.buildings.idf.thermostat import SCHEDULE_VARIABLE, sensor_name, zone_setpoints

    kinds = _own_sides(actions)
    if not any(k for ks in kinds for k in ks):
        return tuple((None,) * len(e.actuators) for e in actions)
    setpoints = zone_setpoints(model)
    nodes = scheduled_setpoints(model) if any("node" in ks for ks in kinds) else {}
    out = []
    for e, ks in zip(actions, kinds, strict=True):
        names = []
        for a, side in zip(e.actuators, ks, strict=True):
            if side == "node":
                schedule = nodes.get(a.key.upper())
            else:
                sp = setpoints.get(a.key.upper()) if side else None
                schedule = getattr(sp, side) if sp else None
            names.append(_hidden(hidden, sensor_name(schedule), SCHEDULE_VARIABLE, schedule) if schedule else None)
        out.append(tuple(names))
    return tuple(out)


def _thermostat_bounds(spec: BuildingSpec, model: list, hidden: list[Sensor]) -> tuple[tuple[str, str], ...]:
    """Each reward zone's bounds: its thermostat's heating and cooling setpoint schedules, read each step. `model`:
    the IDF's objects."""
    from parallel_eplus.buildings.idf.thermostat import SCHEDULE_VARIABLE, sensor_name, zone_setpoints
    from parallel_eplus.buildings.spec.load import SpecError

    setpoints = zone_setpoints(model)
    by_name = {o.name: o for o in spec.observations}
    out, missing = [], []
    for t in spec.reward.temperatures:
        o = by_name[t]
        sp = setpoints.get((o.key or "").upper()) if o.variable == "Zone Mean Air Temperature" else None
        if sp is None or sp.heating is None or sp.cooling is None:
            missing.append(t)
            continue
        low = _hidden(hidden, sensor_name(sp.heating), SCHEDULE_VARIABLE, sp.heating)
        high = _hidden(hidden, sensor_name(sp.cooling), SCHEDULE_VARIABLE, sp.cooling)
        out.append((low, high))
    if missing:
        raise SpecError(
            f'{spec.path}: reward.band = "thermostat", but {missing} read no zone whose thermostat has both a heating '
            f"and a cooling setpoint schedule in {spec.idf.name}; give those zones a band (band = {{ zone = [low, "
            "high], ... }})"
        )
    return tuple(out)


def _hvac_signals(spec: BuildingSpec, hidden: list[Sensor]) -> tuple[tuple[str, str], ...]:
    """(fuel, sensor) for HVAC energy: the spec's `[kpis] hvac` (an observation, else a meter read for the figures),
    by default electricity from the facility's HVAC demand (an observation reading it, else a hidden sensor)."""
    names = {o.name for o in spec.observations}
    if not spec.kpis.hvac:
        seen = [o.name for o in spec.observations if o.variable == HVAC_ELECTRICITY]
        return (("Electricity", seen[0] if seen else _hidden(hidden, "hvac_electricity_w", HVAC_ELECTRICITY,
                                                            "Whole Building")),)  # fmt: skip
    out = []
    for fuel, source in spec.kpis.hvac:
        if source in names:
            out.append((fuel, source))
        elif ":" in source:  # a meter: EnergyPlus names them Fuel:Group (Electricity:HVAC, NaturalGas:HVAC)
            out.append((fuel, _hidden(hidden, f"hvac_{fuel.lower()}_w", source, "", meter=True)))
        else:
            out.append((fuel, _hidden(hidden, f"hvac_{fuel.lower()}_w", source, "Whole Building")))
    return tuple(out)


def load_building(path: str | Path | Building | None = None) -> Building:
    """The building a spec file declares (a path, or a built-in spec's name); None: the data center
    (specs/datacenter-2zone.toml), as a run that names no building has it (`Building.named`). A `Building` is
    resolved already: it is returned as it is. Each spec is resolved once per process."""
    from parallel_eplus.buildings.resources import spec_file

    if isinstance(path, Building):
        return path
    return _load(spec_file(path)) if path else _load(datacenter.DEFAULT_SPEC, named=False)


def weather_path(building: str | Path | Building | None, weather: str) -> Path:
    """The .epw of a weather as a building's spec names it (its short names, the paper's codes, or a path)."""
    from parallel_eplus.buildings.weather.files import resolve_weather

    named = load_building(building).spec.weathers
    return Path(named.get(weather) or resolve_weather(weather))
