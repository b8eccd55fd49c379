"""A building as data: one TOML file (read with the standard library) describes one controllable building.

`load_spec` returns plain frozen dataclasses; every problem in the file is collected and reported at once,
each naming the spec key and its value, so a typo costs one run of the loader rather than a hung worker.
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
            forecasts += parse_forecast(t, where, errors)
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
        occupied = parse_occupancy(r["occupied"], observations, errors)
    obs_names = [o.name for o in observations]
    if r is None:
        errors.append("reward: missing")
        reward = RewardSpec((), "", (0.0, 0.0))
    else:
        temps = need(r, "temperatures", "reward.", list) or []
        for k, t in enumerate(temps):
            if t not in obs_names:
                errors.append(f'reward.temperatures[{k}]: "{t}" is not an observation name{did_you_mean(t, obs_names)}')
        power = need(r, "power", "reward.") or ""
        if power and power not in obs_names:
            errors.append(f'reward.power: "{power}" is not an observation name{did_you_mean(power, obs_names)}')
        band, zone_bands, thermostat = parse_band(r.get("band"), temps, errors)
        energy = need(r, "energy", "reward.", list) if "energy" in r else []
        for k, e in enumerate(energy or []):
            if e not in obs_names:
                errors.append(f'reward.energy[{k}]: "{e}" is not an observation name{did_you_mean(e, obs_names)}')
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
                errors.append(f"reward.{k}: unknown reward parameter{did_you_mean(k, REWARD_KEYS)}")
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
    kpis = parse_kpis(data.get("kpis", {}), [o.name for o in observations], errors, path.parent)
    ventilation = data.get("ventilation", "own")
    if ventilation not in VENTILATION:
        errors.append(f"ventilation: {ventilation!r} is not one of {list(VENTILATION)} (docs/buildings.md)")

    settings = data.get("controller_settings", {})
    if not isinstance(settings, dict) or any(isinstance(v, (dict, list)) for v in settings.values()):
        errors.append("controller_settings: a table of numbers, booleans or strings, e.g. { request_k = 0.02 }")
        settings = {}
    elif settings and not data.get("controller"):
        errors.append("controller_settings: set for no rule; name one with controller = \"module:Class\"")

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
        ventilation=ventilation,
        controller_settings=tuple(settings.items()),
    )
