"""A building as data: one TOML file (read with the standard library) describes one controllable building.

`load_spec` reads the file section by section (one function each here, the optional ones in sections.py) into plain
frozen records (records.py); every problem in the file is collected and reported at once, each naming the spec key
and its value, so a typo costs one run of the loader rather than a hung worker.
"""

from __future__ import annotations

import tomllib
from pathlib import Path
from typing import Any

from parallel_eplus.buildings import resources
from parallel_eplus.buildings.spec.records import (
    OBJECTIVES,
    OCCUPANCY_OBSERVATION,
    READBACKS,
    REWARD_KEYS,
    THERMOSTAT,
    THERMOSTAT_TOLERANCE,
    VENTILATION,
    WEEKDAYS,
    ActionSpec,
    ActuatorSpec,
    BuildingSpec,
    KpiSpec,
    Observation,
    Occupancy,
    RewardSpec,
    SpecError,
)
from parallel_eplus.buildings.spec.sections import did_you_mean, parse_band, parse_forecast, parse_kpis, parse_occupancy
from parallel_eplus.buildings.weather.forecast_features import ForecastSpec

__all__ = [
    "ActionSpec",
    "ActuatorSpec",
    "BuildingSpec",
    "KpiSpec",
    "OBJECTIVES",
    "OCCUPANCY_OBSERVATION",
    "Observation",
    "Occupancy",
    "READBACKS",
    "REWARD_KEYS",
    "RewardSpec",
    "SpecError",
    "THERMOSTAT",
    "THERMOSTAT_TOLERANCE",
    "WEEKDAYS",
    "load_spec",
]


def _resolve(spec: Path, text: str, where: str, errors: list[str]) -> Path:
    """A file the spec names: relative to the spec, absolute, or a bare name among the built-in files.

    Bare names find the package's own models (its agent copies) for its own specs only; in any spec they find the
    EnergyPlus wheel's models, used unmodified (`idf = "RefBldgMediumOfficeNew2004_Chicago.idf"`), and its
    weathers, so `CA = "USA_CA_San.Francisco.Intl.AP.724940_TMY3.epw"` works in any spec: a spec that names only
    those is portable between installs.
    """
    path = (spec.parent / Path(text).expanduser()).resolve()
    if path.is_file():
        return path
    weather = text.lower().endswith(".epw")
    if Path(text).name == text:
        builtin = resources.is_builtin_spec(spec)
        dirs = resources.weather_dirs() if weather else resources.model_dirs()
        if not (weather or builtin):
            dirs = [d for d in dirs if d == resources.energyplus_model_dir()]
        found = [d / text for d in dirs if (d / text).is_file()]
        if found:
            return found[0].resolve()
        dirs = [spec.parent, *dirs]
        looked = ", ".join(dict.fromkeys(map(str, dirs)))
    else:
        looked = str(path.parent)
    errors.append(f'{where}: "{text}" not found (looked in {looked})')
    return path


def load_spec(path: str | Path) -> BuildingSpec:
    """Read and validate a spec; raises SpecError listing every problem (file, key, value)."""
    path = Path(path).resolve()
    data = _read(path)
    errors: list[str] = []  # every section appends its problems here; they are raised together at the end
    name = _need(data, "name", "", errors)
    idf = _model(path, data, errors)
    weathers = {k: _resolve(path, v, f"weathers.{k}", errors) for k, v in data.get("weathers", {}).items()}
    baseline_idf = _resolve(path, data["baseline_idf"], "baseline_idf", errors) if "baseline_idf" in data else None
    observations, forecasts = _observations(data.get("observations", []), errors)
    actions = _actions(data.get("actions", []), errors)
    reward = _reward(data.get("reward"), observations, errors)  # `occupied = { schedule }` adds an observation
    kpis = parse_kpis(data.get("kpis", {}), [o.name for o in observations], errors, path.parent)
    ventilation = _ventilation(data.get("ventilation", "own"), errors)
    controller_settings = _controller_settings(data, errors)
    preset = _preset(data.get("preset"), errors)
    if errors:
        raise SpecError(f"{path}: {len(errors)} problem(s):\n  " + "\n  ".join(errors))
    return BuildingSpec(
        name=name, path=path, idf=idf, observations=tuple(observations), actions=actions, reward=reward,
        weathers=weathers, controller=data.get("controller"), time_features=bool(data.get("time_features", False)),
        schedule_features=bool(data.get("schedule_features", False)),
        timesteps_per_hour=data.get("timesteps_per_hour"), baseline_idf=baseline_idf, kpis=kpis,
        forecasts=tuple(forecasts), ventilation=ventilation, controller_settings=controller_settings, preset=preset,
    )  # fmt: skip


def _read(path: Path) -> dict[str, Any]:
    """The spec file's TOML; a missing or malformed file is a SpecError of its own (nothing else can be read)."""
    try:
        return tomllib.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise SpecError(f"{path}: building spec not found") from None
    except tomllib.TOMLDecodeError as e:
        raise SpecError(f"{path}: malformed TOML: {e}") from None


def _need(table: dict[str, Any], key: str, where: str, errors: list[str], kind: type = str) -> Any:
    """`table[key]` as a `kind` (an integer is a float too); None, with the problem in `errors`, if it is not."""
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


def _bounds(table: dict[str, Any], where: str, errors: list[str]) -> tuple[float | None, float | None]:
    """`low` and `high`, low below high."""
    low, high = _need(table, "low", where, errors, float), _need(table, "high", where, errors, float)
    if low is not None and high is not None and low >= high:
        errors.append(f"{where}low: {low} is not below high {high}")
    return low, high


def _model(spec: Path, data: dict[str, Any], errors: list[str]) -> Path:
    """`idf`: the model the agent acts in (where it is missing, the spec's own path stands in: the error says so)."""
    text = _need(data, "idf", "", errors)
    return _resolve(spec, text, "idf", errors) if text else spec


def _observations(tables: list[dict[str, Any]], errors: list[str]) -> tuple[list[Observation], list[ForecastSpec]]:
    """`[[observations]]`: the sensors (an output variable with its key, or a meter), and the forecasts of the
    episode's weather file (`forecast = ...` entries: sections.py)."""
    observations: list[Observation] = []
    forecasts: list[ForecastSpec] = []
    for i, table in enumerate(tables):
        where = f"observations[{i}]."
        if "forecast" in table:
            forecasts += parse_forecast(table, where, errors)
        else:
            observations.append(_observation(table, where, errors))
    if not observations:
        errors.append("observations: none declared")
    return observations, forecasts


def _observation(table: dict[str, Any], where: str, errors: list[str]) -> Observation:
    name = _need(table, "name", where, errors)
    low, high = _bounds(table, where, errors)
    if ("meter" in table) == ("variable" in table):
        errors.append(f"{where[:-1]}: give either variable (with key) or meter")
    elif "variable" in table:
        _need(table, "key", where, errors)
    return Observation(
        name=name, low=low, high=high, variable=table.get("variable"), key=table.get("key"), meter=table.get("meter"),
        unit=table.get("unit", ""), scale=float(table.get("scale", 1.0)),
    )  # fmt: skip


def _actions(tables: list[dict[str, Any]], errors: list[str]) -> tuple[ActionSpec, ...]:
    """`[[actions]]`: each scaled from [-1, 1] to [low, high] and written to every actuator it lists."""
    return tuple(_action(table, f"actions[{i}].", errors) for i, table in enumerate(tables))


def _action(table: dict[str, Any], where: str, errors: list[str]) -> ActionSpec:
    name = _need(table, "name", where, errors)
    low, high = _bounds(table, where, errors)
    initial = _need(table, "initial", where, errors, float)
    if None not in (low, high, initial) and low < high and not low <= initial <= high:
        errors.append(f"{where}initial: {initial} is outside [{low}, {high}]")
    actuators = tuple(
        ActuatorSpec(
            component=_need(a, "component", f"{where}actuators[{j}].", errors),
            control=_need(a, "control", f"{where}actuators[{j}].", errors),
            key=_need(a, "key", f"{where}actuators[{j}].", errors),
        )
        for j, a in enumerate(_need(table, "actuators", where, errors, list) or [])
    )
    return ActionSpec(
        name=name, low=low, high=high, initial=initial, actuators=actuators, unit=table.get("unit", ""),
        readback_named=_readback(table.get("readback"), where, errors),
    )  # fmt: skip


def _readback(readback: Any, where: str, errors: list[str]) -> tuple[str, str] | None:
    """`readback = { variable = ..., key = ... }`: the output variable holding the building's own choice."""
    if readback is None:
        return None
    if not (isinstance(readback, dict) and isinstance(readback.get("variable"), str) and "key" in readback):
        errors.append(f'{where}readback: {readback!r} is not {{ variable = "...", key = "..." }}')
        return None
    return readback["variable"], str(readback["key"])


def _reward(table: dict[str, Any] | None, observations: list[Observation], errors: list[str]) -> RewardSpec:
    """`[reward]`: which observations are the zones' temperatures, the power and the energy; the comfort band, when
    it applies (`occupied`, which may add an observation) and how far off it still counts; what the energy term
    counts; the reward's own parameters."""
    occupied = None
    if table is not None and "occupied" in table:
        occupied = parse_occupancy(table["occupied"], observations, errors)
    if table is None:
        errors.append("reward: missing")
        return RewardSpec(temperatures=(), power="", band=(0.0, 0.0))
    names = [o.name for o in observations]
    temperatures = _need(table, "temperatures", "reward.", errors, list) or []
    _observation_names(temperatures, "reward.temperatures", names, errors)
    power = _need(table, "power", "reward.", errors) or ""
    if power and power not in names:
        errors.append(f'reward.power: "{power}" is not an observation name{did_you_mean(power, names)}')
    band, zone_bands, thermostat = parse_band(table.get("band"), temperatures, errors)
    energy = (_need(table, "energy", "reward.", errors, list) if "energy" in table else []) or []
    _observation_names(energy, "reward.energy", names, errors)
    objective = _objective(table, errors)
    tolerance = _tolerance(table, thermostat, errors)
    params = _reward_params(table, errors)
    if thermostat:  # the figures' own bounds come from the model; the reward's band, where one is shown
        band = [params.get("lower", band[0]), params.get("upper", band[1])]
    return RewardSpec(
        temperatures=tuple(temperatures), power=power, band=(float(band[0]), float(band[-1])), params=params,
        energy=tuple(energy), occupied=occupied, zone_bands=zone_bands, thermostat=thermostat, objective=objective,
        tolerance=tolerance,
    )  # fmt: skip


def _observation_names(values: list, where: str, names: list[str], errors: list[str]) -> None:
    for k, value in enumerate(values):
        if value not in names:
            errors.append(f'{where}[{k}]: "{value}" is not an observation name{did_you_mean(value, names)}')


def _objective(table: dict[str, Any], errors: list[str]) -> str:
    """`reward.objective`: what the energy term counts (records.OBJECTIVES); energy by default."""
    objective = table.get("objective", "energy")
    if objective not in OBJECTIVES:
        errors.append(f"reward.objective: {objective!r} is not one of {list(OBJECTIVES)}")
        return "energy"
    return objective


def _tolerance(table: dict[str, Any], thermostat: bool, errors: list[str]) -> float:
    """`reward.tolerance`: K a sample may lie outside its bounds and still count in band (thermostat bounds: 0.2)."""
    tolerance = table.get("tolerance", THERMOSTAT_TOLERANCE if thermostat else 0.0)
    if not isinstance(tolerance, (int, float)) or isinstance(tolerance, bool) or tolerance < 0:
        errors.append(f"reward.tolerance: {tolerance!r} is not a number of kelvin >= 0")
        return 0.0
    return float(tolerance)


_SECTION_KEYS = ("temperatures", "power", "band", "energy", "occupied", "objective", "tolerance")


def _reward_params(table: dict[str, Any], errors: list[str]) -> dict[str, float]:
    """The reward's own parameters (records.REWARD_KEYS: RewardConfig's overrides), every other key of `[reward]`."""
    extra = {k: v for k, v in table.items() if k not in _SECTION_KEYS}
    for k in extra:
        if k not in REWARD_KEYS:
            errors.append(f"reward.{k}: unknown reward parameter{did_you_mean(k, REWARD_KEYS)}")
    return {k: float(v) for k, v in extra.items() if k in REWARD_KEYS}


def _ventilation(value: Any, errors: list[str]) -> str:
    """`ventilation`: the controller's copy takes its outdoor air as the model has it ("own") or on demand."""
    if value not in VENTILATION:
        errors.append(f"ventilation: {value!r} is not one of {list(VENTILATION)} (docs/buildings.md)")
    return value


def _preset(value: Any, errors: list[str]) -> str | None:
    """`preset`: what `train --building` trains when no algorithm is named (parallel_eplus/presets/)."""
    if value is None:
        return None
    from parallel_eplus.presets.catalog import names

    if value not in names():
        errors.append(f"preset: {value!r} is not a shipped preset{did_you_mean(str(value), names())}; "
                      f"`parallel-eplus presets` lists them")  # fmt: skip
        return None
    return value


def _controller_settings(data: dict[str, Any], errors: list[str]) -> tuple[tuple[str, Any], ...]:
    """`controller_settings`: the settings of the spec's `controller` (a rule), numbers, booleans or strings."""
    settings = data.get("controller_settings", {})
    if not isinstance(settings, dict) or any(isinstance(v, (dict, list)) for v in settings.values()):
        errors.append("controller_settings: a table of numbers, booleans or strings, e.g. { request_k = 0.02 }")
        return ()
    if settings and not data.get("controller"):
        errors.append('controller_settings: set for no rule; name one with controller = "module:Class"')
    return tuple(settings.items())
