"""A building as data: one TOML file (read with the standard library) describes one controllable building.

`load_spec` returns plain frozen dataclasses; every problem in the file is collected and reported at once,
each naming the spec key and its value, so a typo costs one run of the loader rather than a hung worker.
"""

from __future__ import annotations

import difflib
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from parallel_eplus.buildings import resources
from parallel_eplus.buildings.forecast import ForecastSpec

REWARD_KEYS = ("center", "lower", "upper", "gaussian_weight", "band_weight", "power_weight")
OBJECTIVES = ("energy", "hvac", "cost", "emissions")  # what the reward's energy term counts (buildings/kpis.py)
THERMOSTAT = "thermostat"  # `band = "thermostat"`: each zone's bounds are its own setpoint schedules' values
THERMOSTAT_TOLERANCE = 0.2  # K: the default `reward.tolerance` with thermostat bounds (docs/kpis.md)
WEEKDAYS = ("Mon", "Tue", "Wed", "Thu", "Fri", "Sat", "Sun")
OCCUPANCY_OBSERVATION = "occupancy"  # the observation `occupied = { schedule = ... }` adds


class SpecError(ValueError):
    """Every problem found in one spec file, one per line."""


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
    # each zone's bounds are read each step from its thermostat's schedules (buildings/thermostat.py).
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
    """`[kpis]`: how BOPTEST's figures are counted (buildings/kpis.py). Fuels are EnergyPlus's resource names.

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
    # the learner's side after the sensors and the opt-in features (buildings/forecast.py).
    forecasts: tuple[ForecastSpec, ...] = ()


def _close(value: str, names) -> str:
    match = difflib.get_close_matches(value, list(names), n=1)
    return f'; close: "{match[0]}"' if match else ""


def _resolve(spec: Path, text: str, where: str, errors: list[str]) -> Path:
    """A file the spec names: relative to the spec, absolute, or a bare name among the built-in files.

    Bare names find the package's own models for its own specs only; weathers also among the built-in ones
    (the EnergyPlus wheel's), so `CA = "USA_CA_San.Francisco.Intl.AP.724940_TMY3.epw"` works in any spec.
    """
    path = (spec.parent / Path(text).expanduser()).resolve()
    if path.is_file():
        return path
    weather = text.lower().endswith(".epw")
    if Path(text).name == text and (weather or resources.is_builtin_spec(spec)):
        try:
            return resources.weather_file(text) if weather else resources.model_file(text)
        except FileNotFoundError:
            pass
        dirs = [spec.parent, *(resources.weather_dirs() if weather else resources.model_dirs())]
        looked = ", ".join(dict.fromkeys(map(str, dirs)))
    else:
        looked = str(path.parent)
    errors.append(f'{where}: "{text}" not found (looked in {looked})')
    return path


def load_spec(path: str | Path) -> BuildingSpec:
    """Read and validate a spec; raises SpecError listing every problem (file, key, value)."""
    path = Path(path).resolve()
    try:
        data = tomllib.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise SpecError(f"{path}: building spec not found") from None
    except tomllib.TOMLDecodeError as e:
        raise SpecError(f"{path}: malformed TOML: {e}") from None
    errors: list[str] = []

    def need(table: dict[str, Any], key: str, where: str, kind=str):
        if key not in table:
            errors.append(f"{where}{key}: missing")
            return None
        value = table[key]
        if kind is float and isinstance(value, int) and not isinstance(value, bool):
            value = float(value)
        if not isinstance(value, kind):
            errors.append(f"{where}{key}: {value!r} is not a {kind.__name__}")
            return None
        return value

    def bounds(t: dict[str, Any], where: str) -> tuple[float, float]:
        low, high = need(t, "low", where, float), need(t, "high", where, float)
        if low is not None and high is not None and low >= high:
            errors.append(f"{where}low: {low} is not below high {high}")
        return low, high

    name = need(data, "name", "")
    idf_text = need(data, "idf", "")
    idf = _resolve(path, idf_text, "idf", errors) if idf_text else path
    weathers = {k: _resolve(path, v, f"weathers.{k}", errors) for k, v in data.get("weathers", {}).items()}
    baseline_idf = _resolve(path, data["baseline_idf"], "baseline_idf", errors) if "baseline_idf" in data else None

    observations = []
    forecasts = []
    for i, t in enumerate(data.get("observations", [])):
        where = f"observations[{i}]."
        if "forecast" in t:
            forecasts += _forecast(t, where, errors)
            continue
        n = need(t, "name", where)
        low, high = bounds(t, where)
        if ("meter" in t) == ("variable" in t):
            errors.append(f"{where[:-1]}: give either variable (with key) or meter")
        elif "variable" in t:
            need(t, "key", where)
        observations.append(
            Observation(
                n,
                low,
                high,
                t.get("variable"),
                t.get("key"),
                t.get("meter"),
                t.get("unit", ""),
                float(t.get("scale", 1.0)),
            )
        )
    if not observations:
        errors.append("observations: none declared")

    actions = []
    for i, t in enumerate(data.get("actions", [])):
        where = f"actions[{i}]."
        n = need(t, "name", where)
        low, high = bounds(t, where)
        initial = need(t, "initial", where, float)
        if None not in (low, high, initial) and low < high and not low <= initial <= high:
            errors.append(f"{where}initial: {initial} is outside [{low}, {high}]")
        acts = []
        for j, a in enumerate(need(t, "actuators", where, list) or []):
            aw = f"{where}actuators[{j}]."
            acts.append(ActuatorSpec(need(a, "component", aw), need(a, "control", aw), need(a, "key", aw)))
        readback = t.get("readback")
        if readback is not None and not (
            isinstance(readback, dict) and isinstance(readback.get("variable"), str) and "key" in readback
        ):
            errors.append(f'{where}readback: {readback!r} is not {{ variable = "...", key = "..." }}')
            readback = None
        named = (readback["variable"], str(readback["key"])) if readback else None
        actions.append(ActionSpec(n, low, high, initial, tuple(acts), t.get("unit", ""), named))

    r = data.get("reward")
    occupied = None
    if r is not None and "occupied" in r:
        occupied = _occupancy(r["occupied"], observations, errors)
    obs_names = [o.name for o in observations]
    if r is None:
        errors.append("reward: missing")
        reward = RewardSpec((), "", (0.0, 0.0))
    else:
        temps = need(r, "temperatures", "reward.", list) or []
        for k, t in enumerate(temps):
            if t not in obs_names:
                errors.append(f'reward.temperatures[{k}]: "{t}" is not an observation name{_close(t, obs_names)}')
        power = need(r, "power", "reward.") or ""
        if power and power not in obs_names:
            errors.append(f'reward.power: "{power}" is not an observation name{_close(power, obs_names)}')
        band, zone_bands, thermostat = _band(r.get("band"), temps, errors)
        energy = need(r, "energy", "reward.", list) if "energy" in r else []
        for k, e in enumerate(energy or []):
            if e not in obs_names:
                errors.append(f'reward.energy[{k}]: "{e}" is not an observation name{_close(e, obs_names)}')
        objective = r.get("objective", "energy")
        if objective not in OBJECTIVES:
            errors.append(f"reward.objective: {objective!r} is not one of {list(OBJECTIVES)}")
            objective = "energy"
        tolerance = r.get("tolerance", THERMOSTAT_TOLERANCE if thermostat else 0.0)
        if not isinstance(tolerance, (int, float)) or isinstance(tolerance, bool) or tolerance < 0:
            errors.append(f"reward.tolerance: {tolerance!r} is not a number of kelvin >= 0")
            tolerance = 0.0
        own = ("temperatures", "power", "band", "energy", "occupied", "objective", "tolerance")
        extra = {k: v for k, v in r.items() if k not in own}
        for k in extra:
            if k not in REWARD_KEYS:
                errors.append(f"reward.{k}: unknown reward parameter{_close(k, REWARD_KEYS)}")
        params = {k: float(v) for k, v in extra.items() if k in REWARD_KEYS}
        if thermostat:  # the figures' own bounds come from the model; the reward's band, where one is shown
            band = [params.get("lower", band[0]), params.get("upper", band[1])]
        band_c = (float(band[0]), float(band[-1]))
        reward = RewardSpec(
            tuple(temps),
            power,
            band_c,
            params,
            tuple(energy or ()),
            occupied,
            zone_bands,
            thermostat,
            objective,
            float(tolerance),
        )
    kpis = _kpis(data.get("kpis", {}), [o.name for o in observations], errors)

    if errors:
        raise SpecError(f"{path}: {len(errors)} problem(s):\n  " + "\n  ".join(errors))
    return BuildingSpec(
        name,
        path,
        idf,
        tuple(observations),
        tuple(actions),
        reward,
        weathers,
        data.get("controller"),
        bool(data.get("time_features", False)),
        bool(data.get("schedule_features", False)),
        data.get("timesteps_per_hour"),
        baseline_idf,
        kpis=kpis,
        forecasts=tuple(forecasts),
    )


FORECAST_KEYS = {"name", "forecast", "hours", "steps", "stride", "error", "low", "high"}


def _forecast(t: dict[str, Any], where: str, errors: list[str]) -> list[ForecastSpec]:
    """`{ name = "outdoor_next", forecast = "drybulb", hours = 6 }`: the next 6 hours of the EPW's dry bulb;
    `steps = 8` instead counts control steps; `stride` (default 1, in the same unit); `error = "low"`, "medium"
    or "high" adds BOPTEST's forecast error; `low`/`high`: the bounds (default the EPW's, -70 and 70)."""
    unknown = sorted(set(t) - FORECAST_KEYS)
    if unknown:
        errors.append(f"{where[:-1]}: unknown key(s) {unknown}; a forecast takes {sorted(FORECAST_KEYS)}")
    if ("hours" in t) == ("steps" in t):
        errors.append(f"{where[:-1]}: a forecast gives either hours or steps (how many values)")
        return []
    count = t.get("hours", t.get("steps"))
    try:
        return [ForecastSpec(str(t.get("name", t["forecast"])), str(t["forecast"]), int(count),
                             float(t.get("stride", 1)), "steps" in t, t.get("error"),
                             float(t.get("low", -70.0)), float(t.get("high", 70.0)))]  # fmt: skip
    except (ValueError, TypeError) as e:
        errors.append(f"{where}forecast: {e}")
        return []


def _occupancy(table: Any, observations: list[Observation], errors: list[str]) -> Occupancy | None:
    """`reward.occupied`: { schedule = NAME } (its value, read each step, added as the `occupancy` observation
    unless one reads it already), { observation = NAME }, or { hours = [start, end], weekdays = ["Mon", ...] }."""
    where = "reward.occupied"
    if not isinstance(table, dict):
        errors.append(f'{where}: {table!r} is not a table such as {{ schedule = "OCC_SCH" }}')
        return None
    unknown = set(table) - {"schedule", "observation", "above", "hours", "weekdays", "high"}
    if unknown:
        errors.append(f"{where}: unknown key(s) {sorted(unknown)}; use schedule, observation, above, hours, weekdays")
    kinds = [k for k in ("schedule", "observation", "hours") if k in table]
    if len(kinds) != 1:
        errors.append(f"{where}: give one of schedule, observation or hours (got {kinds or 'none'})")
        return None
    above = table.get("above", 0.0)
    if not isinstance(above, (int, float)) or isinstance(above, bool):
        errors.append(f"{where}.above: {above!r} is not a number")
        above = 0.0
    if "hours" in table:
        hours, days = table["hours"], table.get("weekdays", list(WEEKDAYS))
        if not (isinstance(hours, list) and len(hours) == 2 and all(isinstance(h, (int, float)) for h in hours)
                and 0 <= hours[0] < hours[1] <= 24):  # fmt: skip
            errors.append(f"{where}.hours: {hours!r} is not [start, end] with 0 <= start < end <= 24")
            hours = [0, 24]
        bad = [d for d in days if d not in WEEKDAYS] if isinstance(days, list) else [days]
        if bad:
            errors.append(f"{where}.weekdays: {bad} not among {list(WEEKDAYS)}")
            days = list(WEEKDAYS)
        return Occupancy(hours=(float(hours[0]), float(hours[1])), weekdays=tuple(WEEKDAYS.index(d) for d in days))
    if "observation" in table:
        name = table["observation"]
        names = [o.name for o in observations]
        if name not in names:
            errors.append(f'{where}.observation: "{name}" is not an observation name{_close(str(name), names)}')
        return Occupancy(observation=str(name), above=float(above))
    schedule = table["schedule"]
    if not isinstance(schedule, str) or not schedule:
        errors.append(f"{where}.schedule: {schedule!r} is not a schedule name")
        return None
    for o in observations:  # an observation reading this schedule already
        if o.variable == "Schedule Value" and (o.key or "").lower() == schedule.lower():
            return Occupancy(observation=o.name, above=float(above))
    if any(o.name == OCCUPANCY_OBSERVATION for o in observations):
        errors.append(
            f'{where}.schedule: an observation is named "{OCCUPANCY_OBSERVATION}" already; read the schedule there '
            '(variable = "Schedule Value") and give occupied = { observation = ... }'
        )
        return None
    high = float(table.get("high", 1.0))  # a fraction schedule; a head-count one gives its maximum
    observations.append(Observation(OCCUPANCY_OBSERVATION, 0.0, high, "Schedule Value", schedule))
    return Occupancy(observation=OCCUPANCY_OBSERVATION, above=float(above))


def _band(value: Any, temps: list[str], errors: list[str]):
    """`reward.band`: [low, high] for every zone, { zone = [low, high], ... } per zone (every temperature named),
    or "thermostat". Returns (band, zone bands or None, thermostat)."""
    where = "reward.band"

    def pair(v, at) -> list[float]:
        if not (isinstance(v, list) and len(v) == 2 and all(isinstance(x, (int, float)) for x in v) and v[0] < v[1]):
            errors.append(f"{at}: {v!r} is not [low, high] with low below high")
            return [0.0, 1.0]
        return [float(v[0]), float(v[1])]

    if value is None:
        errors.append(f'{where}: missing ([low, high], {{ zone = [low, high], ... }} or "{THERMOSTAT}")')
        return [0.0, 1.0], None, False
    if value == THERMOSTAT:
        return [20.0, 25.0], None, True
    if isinstance(value, dict):
        unknown = [k for k in value if k not in temps]
        for k in unknown:
            errors.append(f"{where}.{k}: not among reward.temperatures{_close(k, temps)}")
        missing = [t for t in temps if t not in value]
        if missing:
            errors.append(f"{where}: no band for {missing}")
        zones = tuple(tuple(pair(value[t], f"{where}.{t}")) for t in temps if t in value)
        if not zones:
            return [0.0, 1.0], None, False
        return [min(z[0] for z in zones), max(z[1] for z in zones)], zones, False
    if isinstance(value, str):
        errors.append(f'{where}: {value!r} is not "{THERMOSTAT}", [low, high] or a table of zones')
        return [0.0, 1.0], None, False
    return pair(value, where), None, False


def _kpis(table: Any, obs_names: list[str], errors: list[str]) -> KpiSpec:
    """`[kpis]` (all optional): hvac, tariff, emissions per fuel; floor_area_m2."""
    if not isinstance(table, dict):
        errors.append(f"kpis: {table!r} is not a table")
        return KpiSpec()
    unknown = set(table) - {"hvac", "tariff", "emissions", "floor_area_m2"}
    if unknown:
        errors.append(f"kpis: unknown key(s) {sorted(unknown)}; use hvac, tariff, emissions, floor_area_m2")
    tables = {}
    for key in ("hvac", "tariff", "emissions"):
        t = table.get(key, {})
        if not isinstance(t, dict):
            errors.append(f"kpis.{key}: {t!r} is not a table of fuels, e.g. {{ Electricity = ..., NaturalGas = ... }}")
            t = {}
        tables[key] = t
    for fuel, source in tables["hvac"].items():
        if not isinstance(source, str) or not source:
            errors.append(f"kpis.hvac.{fuel}: {source!r} is not an observation, meter or variable name")
    for fuel, factor in tables["emissions"].items():
        if not isinstance(factor, (int, float)) or isinstance(factor, bool) or factor < 0:
            errors.append(f"kpis.emissions.{fuel}: {factor!r} is not kg CO2e per kWh (a number >= 0)")
    for fuel, price in tables["tariff"].items():
        ok = isinstance(price, (int, float)) and not isinstance(price, bool)
        if isinstance(price, dict):
            keys = set(price)
            ok = keys <= {"day", "night", "day_hours", "weekdays_only"} and {"day", "night"} <= keys
            ok = ok or keys == {"csv"} and isinstance(price["csv"], str)
        if not ok:
            errors.append(
                f"kpis.tariff.{fuel}: {price!r} is not a price per kWh, {{ day = .., night = .., day_hours = [7, 22] }}"
                ' or { csv = "prices.csv" }'
            )
    area = table.get("floor_area_m2")
    if area is not None and not (isinstance(area, (int, float)) and area > 0):
        errors.append(f"kpis.floor_area_m2: {area!r} is not a positive number")
        area = None
    return KpiSpec(
        tuple((f, str(v)) for f, v in tables["hvac"].items()),
        tuple(tables["tariff"].items()),
        tuple((f, float(v)) for f, v in tables["emissions"].items() if isinstance(v, (int, float))),
        float(area) if area else None,
    )


def reward_config(spec: BuildingSpec):
    """The spec's reward parameters as today's RewardConfig (center/lower/upper are in C there)."""
    from parallel_eplus.buildings.reward import RewardConfig

    suffix = {"center": "center_c", "lower": "lower_c", "upper": "upper_c"}
    return RewardConfig(**{suffix.get(k, k): v for k, v in spec.reward.params.items()})
