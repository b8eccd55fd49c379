"""Choosing among a sweep's trials by evaluation, and handing the choice on as a ready command.

A trial's evaluation is its best one (the policy kept as best/model.zip): `eval_score` (training/eval_target.py:
with a target, meeting it first, then the lowest energy against the built-in controller; without, the highest
mean reward) and that evaluation's KPIs. Ray Tune's searchers and schedulers get these with every result
(tune_trial.py); the closing table and `runs show SWEEP` rank by them.
"""

from __future__ import annotations

import json
import math
import shlex
from pathlib import Path

import pandas as pd

from parallel_eplus import io
from parallel_eplus.runs.run_files import ALL_WEATHERS, EVALUATIONS_FILE

KPIS = ("in_band_pct", "energy_change_pct", "reward_mean", "power_kw")
BEST_FILE = "best.toml"  # the chosen trial's settings as a sweep over seeds: `parallel-eplus sweep <it>`
COMMAND_FILE = "best-command.txt"

# config.json keys that `train` takes as flags (a key without one is written to best.toml only)
FLAGS = {
    "workers": "--workers", "weathers": "--weathers", "model": "--model", "building": "--building",
    "timesteps": "--timesteps", "run_days": "--run-days", "batch_size": "--batch-size", "seed": "--seed",
    "algorithm": "--algorithm", "residual_scale": "--residual", "residual_space": "--residual-space",
    "rbc_target_c": "--rbc-target", "time_features": "--time-features", "schedule_features": "--schedule-features",
    "init_from": "--init-from", "init_from_baseline": "--init-from-baseline", "checkpoint_every": "--checkpoint-every",
    "keep_episodes": "--keep-episodes", "lockstep": "--lockstep", "overlap": "--overlap",
    "max_restarts": "--max-restarts", "step_timeout_s": "--step-timeout", "comfort.target_pct": "--comfort-target",
    "comfort.margin_c": "--comfort-margin", "trpo.gamma": "--gamma", "trpo.gae_lambda": "--gae-lambda",
    "trpo.log_std_init": "--log-std-init", "trpo.sde_sample_freq": "--sde-freq", "evaluation.every": "--eval-every",
    "evaluation.weathers": "--eval-weathers", "evaluation.days": "--eval-days", "evaluation.target": "--target",
}  # fmt: skip


def trial_evaluation(run_dir: Path) -> dict:
    """`eval_score` and the KPIs (`eval_<kpi>`) of the run's best evaluation so far, its step
    (`eval_timesteps`) and whether any evaluation met the target (`eval_target_met`); NaN before the first."""
    out = {"eval_score": math.nan, "eval_timesteps": -1, "eval_target_met": 0.0}
    out |= {f"eval_{k}": math.nan for k in KPIS}
    try:
        df = pd.read_csv(Path(run_dir) / EVALUATIONS_FILE)
    except (OSError, ValueError):
        return out
    means = df[df["weather"] == ALL_WEATHERS] if "weather" in df else df.iloc[0:0]
    if means.empty or "score" not in means:
        return out
    best = means.loc[means["score"].idxmax()]
    out |= {"eval_score": float(best["score"]), "eval_timesteps": int(best["timesteps"])}
    out |= {f"eval_{k}": float(best[k]) for k in KPIS if k in best}
    out["eval_target_met"] = float(means.get("target_met", pd.Series([0.0])).max())
    return out


def best_of(rows: list[dict], metric: str, mode: str) -> dict | None:
    """The row with the best `metric` (NaN never wins)."""
    known = [r for r in rows if r.get(metric) == r.get(metric) and r.get(metric) is not None]
    if not known:
        return None
    return (max if mode == "max" else min)(known, key=lambda r: r[metric])


def _flat(config: dict) -> dict:
    out = {}
    for key, value in config.items():
        if isinstance(value, dict):
            out |= {f"{key}.{k}": v for k, v in value.items()}
        else:
            out[key] = value
    return out


def command_line(config: dict, defaults: dict) -> tuple[str, list[str]]:
    """`parallel-eplus train ...` for a run's config.json (the settings that differ from the defaults), and
    the differing settings no flag takes."""
    args, missing = ["parallel-eplus", "train"], []
    flat, base = _flat(config), _flat(defaults)
    skip = {"run_name", "runs_dir", "tensorboard_dir", "backend", "ray_address", "workers_per_actor"}
    for key, value in flat.items():
        if key in skip or value == base.get(key) or (key == "building" and value is None):
            continue
        flag = FLAGS.get(key)
        if flag is None:
            missing.append(key)
        elif isinstance(value, bool):
            args += [flag] if value else []
        elif isinstance(value, list):
            args += [flag, ",".join(map(str, value))]
        elif value is not None:
            args += [flag, str(value)]
    return shlex.join(args), missing


def _toml_value(value) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(_toml_value(v) for v in value) + "]"
    return json.dumps(value)  # numbers and strings read back the same in TOML


def write_choice(sweep_dir: Path, sweep_name: str, trial_dir: Path, defaults: dict, seeds=(0, 1, 2)) -> list[str]:
    """The chosen trial as `best.toml` (its settings over seeds, a ready sweep) and `best-command.txt`; returns
    the lines to print."""
    config = json.loads((trial_dir / "config.json").read_text())
    flat = {k: v for k, v in _flat(config).items() if v is not None and v != _flat(defaults).get(k)}
    for key in ("run_name", "runs_dir", "tensorboard_dir", "seed", "backend", "ray_address", "workers_per_actor"):
        flat.pop(key, None)
    lines = [f"# the best trial of sweep {sweep_name}: {trial_dir.name}, chosen by evaluation",
             f'name = "{sweep_name}-best"', f"seeds = {_toml_value(list(seeds))}", "", "[train]"]  # fmt: skip
    lines += [f'"{k}" = {_toml_value(v)}' if "." in k else f"{k} = {_toml_value(v)}" for k, v in flat.items()]
    io.write_text(sweep_dir / BEST_FILE, "\n".join(lines) + "\n")
    command, missing = command_line(config, defaults)
    sweep_command = f"parallel-eplus sweep {sweep_dir / BEST_FILE}"
    text = [f"best configuration ({trial_dir.name}):", f"  {command}"]
    if missing:
        text[-1] += f"   # not a flag: {', '.join(missing)}: use the sweep below"
    text.append(f"  {sweep_command}   # the same over seeds {','.join(map(str, seeds))}")
    io.write_text(sweep_dir / COMMAND_FILE, "\n".join(text) + "\n")
    return text
