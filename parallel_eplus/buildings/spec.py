"""A building as data: one TOML file (read with the standard library) describes one controllable building.

`load_spec` returns plain frozen dataclasses; every problem in the file is collected and reported at once,
each naming the spec key and its value, so a typo costs one run of the loader rather than a hung worker.
Not wired into the env yet: see docs/buildings.md (to come) and issue 22.
"""

from __future__ import annotations

import difflib
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

REWARD_KEYS = ("center", "lower", "upper", "gaussian_weight", "band_weight", "power_weight")


class SpecError(ValueError):
    """Every problem found in one spec file, one per line."""


@dataclass(frozen=True)
class Observation:
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
    component: str
    control: str
    key: str


@dataclass(frozen=True)
class ActionSpec:
    name: str
    low: float
    high: float
    initial: float
    actuators: tuple[ActuatorSpec, ...]
    unit: str = ""


@dataclass(frozen=True)
class RewardSpec:
    temperatures: tuple[str, ...]
    power: str
    band: tuple[float, float]
    params: dict[str, float] = field(default_factory=dict)  # optional RewardConfig overrides


@dataclass(frozen=True)
class BuildingSpec:
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
    baseline_idf: Path | None = None  # the model's own controls, for evaluation; None: `idf` without actuators


def _close(value: str, names) -> str:
    match = difflib.get_close_matches(value, list(names), n=1)
    return f'; close: "{match[0]}"' if match else ""


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
    idf = (path.parent / idf_text).resolve() if idf_text else path
    if idf_text and not idf.is_file():
        errors.append(f'idf: "{idf_text}" not found (looked in {path.parent})')
    weathers = {k: (path.parent / v).resolve() for k, v in data.get("weathers", {}).items()}

    observations = []
    for i, t in enumerate(data.get("observations", [])):
        where = f"observations[{i}]."
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
        actions.append(ActionSpec(n, low, high, initial, tuple(acts), t.get("unit", "")))

    obs_names = [o.name for o in observations]
    r = data.get("reward")
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
        band = need(r, "band", "reward.", list) or [0.0, 0.0]
        if len(band) != 2 or band[0] >= band[1]:
            errors.append(f"reward.band: {band} is not [low, high] with low below high")
        extra = {k: v for k, v in r.items() if k not in ("temperatures", "power", "band")}
        for k in extra:
            if k not in REWARD_KEYS:
                errors.append(f"reward.{k}: unknown reward parameter{_close(k, REWARD_KEYS)}")
        params = {k: float(v) for k, v in extra.items() if k in REWARD_KEYS}
        reward = RewardSpec(tuple(temps), power, (float(band[0]), float(band[-1])), params)

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
        (path.parent / data["baseline_idf"]).resolve() if "baseline_idf" in data else None,
    )


def reward_config(spec: BuildingSpec):
    """The spec's reward parameters as today's RewardConfig (center/lower/upper are in C there)."""
    from parallel_eplus.buildings.reward import RewardConfig

    suffix = {"center": "center_c", "lower": "lower_c", "upper": "upper_c"}
    return RewardConfig(**{suffix.get(k, k): v for k, v in spec.reward.params.items()})
