"""A sweep's specification: every trial's `train` settings, a grid or a search over any of them, and seeds.

A sweep is a small TOML file (docs/training.md shows one). Its keys are a run's own `config.json` keys
(TrainConfig's fields; `reward.power_weight`, `trpo.target_kl`, ... for the nested ones), so what a sweep
varies reads the same as what a run saved. Key names are checked here, before anything starts; values
are checked by each trial (TrainConfig.resolved), so one bad value fails that trial and not the sweep.
"""

from __future__ import annotations

import json
import re
import tomllib
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

from parallel_eplus.buildings.scoring.reward import RewardConfig
from parallel_eplus.learning.model_based.runtime.renamed import renamed
from parallel_eplus.training.config import TrainConfig

# Where a trial runs is the sweep's business: each trial trains with the local backend on its node.
NOT_SWEPT = {"backend", "ray_address", "workers_per_actor", "run_name", "runs_dir", "tensorboard_dir"}
PATH_KEYS = ("building", "init_from")  # resolved where the sweep starts: a trial runs in a folder of Tune's
DISTRIBUTIONS = ("uniform", "loguniform", "choice", "randint")
# The last training batch's (a stochastic policy on one batch), or a trial's best evaluation's (`eval_...`: the
# frozen policy on the validation weathers; needs `evaluation.every`); eval_score is training/eval_target.py's.
METRICS = {"in_band_pct": "max", "power_kw": "min", "reward": "max", "eval_score": "max", "eval_in_band_pct": "max",
           "eval_energy_change_pct": "min", "eval_reward_mean": "max"}  # fmt: skip
SCHEDULERS = ("asha", "pbt")


@dataclass
class SchedulerSpec:
    """Ray Tune's trial scheduler over the trials' results (`timesteps` is its clock): ASHA stops the trials
    that trail the others at each rung; PBT copies the leaders' weights into the trailers and perturbs their
    `mutations` settings. Both judge by `metric` (default eval_score)."""

    kind: str  # "asha" or "pbt"
    metric: str = "eval_score"
    mode: str = ""
    grace_period: int = 0  # ASHA: env steps before a trial can be stopped; 0: one evaluation's (evaluation.every)
    reduction_factor: int = 2  # ASHA: 1/this of the trials go on at each rung
    interval: int = 0  # PBT: env steps between exploits; 0: evaluation.every
    mutations: dict[str, list] = field(default_factory=dict)  # PBT: key -> values to choose from
    quantile_fraction: float = 0.25  # PBT: the bottom share of trials copies the top share


@dataclass
class SearchSpec:
    """Optuna's search through Ray Tune: `samples` trials, each drawn from `space`, judged by `metric`."""

    space: dict[str, dict[str, list]]  # key -> {"loguniform": [low, high]}, {"choice": [...]}, ...
    samples: int = 8
    metric: str = "in_band_pct"
    mode: str = ""  # "max" or "min"; default: the metric's natural direction (METRICS)


@dataclass
class SweepSpec:
    """Every trial's settings (`base`), what varies (`grid` or `search`), and the seeds each runs with."""

    name: str
    base: dict[str, Any] = field(default_factory=dict)  # dotted TrainConfig keys -> values
    grid: dict[str, list] = field(default_factory=dict)
    seeds: list[int] = field(default_factory=lambda: [0])
    search: SearchSpec | None = None
    scheduler: SchedulerSpec | None = None
    runs_dir: str = "runs"
    tensorboard_dir: str = "tensorboard_logs"

    @property
    def varied(self) -> list[str]:
        """The keys that tell trials apart, in the order trial names show them."""
        keys = list(self.grid) + (list(self.search.space) if self.search else [])
        return keys + (["seed"] if len(self.seeds) > 1 or not keys else [])

    def to_json(self) -> str:
        return json.dumps(asdict(self), indent=2, sort_keys=True)


def _nested() -> set[str]:
    """TrainConfig's fields that are settings of their own (reward, trpo, ppo, sac, comfort, ...)."""
    return {name for name, value in asdict(TrainConfig(workers=1)).items() if isinstance(value, dict)}


def _flatten(table: dict, prefix: str = "") -> dict[str, Any]:
    out = {}
    for key, value in table.items():
        key = prefix + key.replace("-", "_")
        if isinstance(value, dict) and not prefix and key in _nested():
            out |= _flatten(value, key + ".")
        elif key.startswith("mpc."):
            out.update([_renamed(key, value)])
        else:
            out[key] = value
    return out


def _renamed(key: str, value: Any) -> tuple[str, Any]:
    """A planner setting (`mpc.own_radius`) by its name and values now (runtime/renamed.py), with the warning: a
    single value, a grid's or mutations' list, or a search space's {distribution: [values]}."""
    name = key.removeprefix("mpc.")
    if isinstance(value, list):
        value = [renamed(name, v, "a sweep spec")[1] for v in value]
    elif isinstance(value, dict):
        value = {d: [renamed(name, v, "a sweep spec")[1] for v in vs] if isinstance(vs, list) else vs
                 for d, vs in value.items()}  # fmt: skip
    else:
        name, value = renamed(name, value, "a sweep spec")
    return "mpc." + renamed(name, None, "a sweep spec")[0], value


def config_keys() -> set[str]:
    """Every key a sweep may set: TrainConfig's fields, the nested ones dotted."""
    keys = set()
    for name, value in asdict(TrainConfig(workers=1)).items():
        keys |= {f"{name}.{k}" for k in value} if isinstance(value, dict) else {name}
    return keys - NOT_SWEPT


def _check_keys(keys, where: str) -> None:
    known = config_keys()
    for key in keys:
        if key in NOT_SWEPT:
            raise ValueError(f"{where}: {key!r} is the sweep's to set (each trial trains locally on its node; "
                             "the sweep command takes --ray-address)")  # fmt: skip
        if key not in known:
            close = sorted(k for k in known if k.split(".")[-1] == key.split(".")[-1]) or sorted(known)
            raise ValueError(f"{where}: unknown setting {key!r}; use a run's config.json keys, e.g. {', '.join(close)}")


def _resolved_paths(values: dict[str, Any]) -> dict[str, Any]:
    out = dict(values)
    for key in PATH_KEYS:
        if isinstance(out.get(key), str) and Path(out[key]).exists():
            out[key] = str(Path(out[key]).resolve())
    return out


def load_spec(path: str | Path) -> SweepSpec:
    """Read and check a sweep's TOML file (key names; values are each trial's to check)."""
    path = Path(path)
    try:
        raw = tomllib.loads(path.read_text())
    except tomllib.TOMLDecodeError as e:
        raise ValueError(f"{path}: not valid TOML ({e})") from None
    unknown = set(raw) - {"name", "seeds", "train", "grid", "search", "scheduler", "runs_dir", "tensorboard_dir"}
    if unknown:
        raise ValueError(f"{path}: unknown section(s) {sorted(unknown)}; a sweep has name, seeds, [train], [grid], "
                         "[search], [scheduler], runs_dir, tensorboard_dir")  # fmt: skip
    train = _flatten(raw.get("train", {}))
    if isinstance(train.get("reward"), str):  # a reward file, as `train --reward FILE.json` takes
        train |= {f"reward.{k}": v for k, v in asdict(RewardConfig.from_any(train.pop("reward"))).items()}
    if isinstance(train.get("weathers"), str):
        train["weathers"] = [w.strip() for w in train["weathers"].split(",") if w.strip()]
    grid = _flatten(raw.get("grid", {}))
    search = None
    if "search" in raw:
        s = dict(raw["search"])
        space = _flatten(s.pop("space", {}))
        unknown = set(s) - {"samples", "metric", "mode"}
        if unknown or not space:
            raise ValueError(f"{path}: [search] takes samples, metric, mode and a [search.space] table")
        search = SearchSpec(space=space, **s)
    scheduler = None
    if "scheduler" in raw:
        s = dict(raw["scheduler"])
        kind = s.pop("type", None)
        mutations = _flatten(s.pop("mutations", {}))
        fields = {"metric", "mode", "grace_period", "reduction_factor", "interval", "quantile_fraction"}
        if kind not in SCHEDULERS or set(s) - fields:
            raise ValueError(f"{path}: [scheduler] takes type (asha or pbt), metric, mode, grace_period, "
                             "reduction_factor (ASHA), interval and a [scheduler.mutations] table (PBT)")  # fmt: skip
        scheduler = SchedulerSpec(kind=kind, mutations=mutations, **s)
    spec = SweepSpec(
        name=str(raw.get("name") or path.stem), base=train, grid=grid, search=search, scheduler=scheduler,
        seeds=list(raw.get("seeds", [train.get("seed", 0)])), runs_dir=raw.get("runs_dir", "runs"),
        tensorboard_dir=raw.get("tensorboard_dir", "tensorboard_logs"),
    )  # fmt: skip
    check(spec, str(path))
    return spec


def check(spec: SweepSpec, where: str = "sweep") -> None:
    """Key names, grid lists, the search's space and metric, seeds and the name: all before anything runs."""
    if not re.fullmatch(r"[A-Za-z0-9][A-Za-z0-9._=-]*", spec.name):
        raise ValueError(f"{where}: name {spec.name!r} must be a folder name (letters, digits, . _ = -)")
    _check_keys(spec.base, f"{where} [train]")
    _check_keys(spec.grid, f"{where} [grid]")
    for key, values in spec.grid.items():
        if not isinstance(values, list) or not values:
            raise ValueError(f"{where} [grid]: {key} takes a list of values, e.g. {key} = [1, 2]")
    if not spec.seeds or not all(isinstance(s, int) for s in spec.seeds) or len(set(spec.seeds)) < len(spec.seeds):
        raise ValueError(f"{where}: seeds takes distinct whole numbers, e.g. seeds = [0, 1, 2]")
    if "seed" in spec.grid:
        raise ValueError(f"{where}: give seeds as `seeds = [...]`, not in [grid]")
    if spec.search is not None:
        s = spec.search
        if spec.grid:
            raise ValueError(f"{where}: a sweep has a [grid] or a [search], not both")
        if len(spec.seeds) > 1:
            raise ValueError(f"{where}: a search draws its trials; give it one seed (then run the best with seeds)")
        _check_keys(s.space, f"{where} [search.space]")
        for key, dist in s.space.items():
            if not isinstance(dist, dict) or len(dist) != 1 or next(iter(dist)) not in DISTRIBUTIONS:
                raise ValueError(f"{where} [search.space]: {key} takes one of {', '.join(DISTRIBUTIONS)}, e.g. "
                                 f"{key} = {{ loguniform = [1e-4, 1e-2] }}")  # fmt: skip
        _check_metric(spec, s, f"{where} [search]")
        if s.samples < 1:
            raise ValueError(f"{where} [search]: samples at least 1")
    if spec.scheduler is not None:
        _check_scheduler(spec, where)
    spec.base = _resolved_paths(spec.base)
    spec.grid = {k: [_resolved_paths({k: v})[k] for v in vs] for k, vs in spec.grid.items()}


def evaluates(spec: SweepSpec) -> bool:
    """Whether every trial evaluates its policy during training (`evaluation.every` in [train])."""
    return bool(spec.base.get("evaluation.every"))


def _check_metric(spec: SweepSpec, s, where: str) -> None:
    if s.metric not in METRICS:
        raise ValueError(f"{where}: metric is one of {', '.join(METRICS)}")
    if s.metric.startswith("eval_") and not evaluates(spec):
        raise ValueError(f"{where}: metric {s.metric} is an evaluation's: set evaluation.every in [train] "
                         "(e.g. [train.evaluation] every = 4096)")  # fmt: skip
    s.mode = s.mode or METRICS[s.metric]
    if s.mode not in ("max", "min"):
        raise ValueError(f"{where}: mode is max or min")


def _check_scheduler(spec: SweepSpec, where: str) -> None:
    s = spec.scheduler
    _check_metric(spec, s, f"{where} [scheduler]")
    every = int(spec.base.get("evaluation.every") or 0)
    s.grace_period = s.grace_period or every
    s.interval = s.interval or every
    if s.kind == "asha" and (s.grace_period < 1 or s.reduction_factor < 2):
        raise ValueError(f"{where} [scheduler]: ASHA takes grace_period >= 1 env steps and reduction_factor >= 2")
    if s.kind == "pbt":
        if s.interval < 1 or not s.mutations:
            raise ValueError(f"{where} [scheduler]: PBT takes interval >= 1 env steps and a [scheduler.mutations] "
                             'table, e.g. "trpo.target_kl" = [0.005, 0.01, 0.02]')  # fmt: skip
        _check_keys(s.mutations, f"{where} [scheduler.mutations]")
        from parallel_eplus.training.resume_settings import MUTABLE_KEYS

        fixed = sorted(set(s.mutations) - set(MUTABLE_KEYS))
        if fixed:
            raise ValueError(f"{where} [scheduler.mutations]: PBT can change {', '.join(MUTABLE_KEYS)} mid-run, not "
                             f"{', '.join(fixed)} (they change the network or the buffers)")  # fmt: skip
        if spec.grid or spec.search:
            raise ValueError(f"{where}: PBT copies weights between trials of one configuration: give it seeds and "
                             "[scheduler.mutations], not a [grid] or [search]")  # fmt: skip
        if not 0 < s.quantile_fraction <= 0.5:
            raise ValueError(f"{where} [scheduler]: quantile_fraction is within (0, 0.5]")
        for key, values in s.mutations.items():
            if not isinstance(values, list) or not values:
                raise ValueError(f"{where} [scheduler.mutations]: {key} takes a list of values")


def seeds_spec(cfg: TrainConfig, seeds: list[int]) -> SweepSpec:
    """`train ... --seeds 0,1,2`: the same run once per seed, as a sweep named after the run."""
    values = asdict(cfg)
    base = {}
    for key, value in values.items():
        if isinstance(value, dict):
            base |= {f"{key}.{k}": v for k, v in value.items()}
        elif key not in NOT_SWEPT and key != "seed":
            base[key] = value
    spec = SweepSpec(name=str(cfg.run_name), base=base, seeds=seeds, runs_dir=cfg.runs_dir,
                     tensorboard_dir=cfg.tensorboard_dir)  # fmt: skip
    check(spec, "--seeds")
    return spec


def trial_config(settings: dict[str, Any], runs_dir: str, tensorboard_dir: str, name: str) -> TrainConfig:
    """One trial's TrainConfig: the dotted settings over the defaults, its folders under the sweep's."""
    values = asdict(TrainConfig())
    for key, value in settings.items():
        head, _, tail = key.partition(".")
        if tail:
            values[head][tail] = value
        else:
            values[key] = value
    values |= {"runs_dir": runs_dir, "tensorboard_dir": tensorboard_dir, "run_name": name, "backend": "local",
               "ray_address": None, "workers_per_actor": None}  # fmt: skip
    try:
        return TrainConfig.from_json(json.dumps(values))
    except TypeError as e:
        raise ValueError(f"trial {name}: {e}") from None


def trial_name(config: dict[str, Any], varied: list[str], prefix: str | None = None) -> str:
    """A trial's folder name from what tells it apart, e.g. `algorithm-ppo_seed-1` (a search's: `<trial id>_...`,
    so that trials drawn with the same shown values, or by a search run again, never share a folder).

    No `=`: `evaluate --policy PATH=LABEL` reads one as the start of a label."""

    def shown(value) -> str:
        if isinstance(value, (list, tuple)):
            return "+".join(shown(v) for v in value)
        if isinstance(value, str) and "/" in value:  # a file: its name
            value = Path(value).stem
        text = f"{value:.4g}" if isinstance(value, float) else str(value)
        if isinstance(value, (int, float)) and not isinstance(value, bool):
            return text  # a number keeps its sign: log_std_init--0.5
        return re.sub(r"[^A-Za-z0-9.+-]+", "-", text).strip("-") or "x"

    parts = [f"{key.split('.')[-1]}-{shown(config[key])}" for key in varied if key in config]
    return "_".join(([prefix] if prefix else []) + parts) or "trial"
