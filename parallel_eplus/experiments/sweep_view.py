"""`parallel-eplus runs show SWEEP`: one table of a sweep's trials: what each varies, its state and steps, its
best evaluation (the one kept as best/model.zip) and, marked *, the trial the sweep chooses (sweep_rank.py)."""

from __future__ import annotations

import json
import math
from pathlib import Path

from parallel_eplus.experiments.registry_view import duration
from parallel_eplus.experiments.sweep_rank import best_of, trial_evaluation
from parallel_eplus.runs.registry import list_runs
from parallel_eplus.runs.run_files import TARGET_FILE, read_json

SWEEP_FILE = "sweep.json"


def find_sweep(name: str | Path, folder: Path) -> Path | None:
    """A sweep's folder from its name under `folder` or its path; None if it is not one."""
    for path in (Path(folder) / name, Path(name)):
        if (path / SWEEP_FILE).is_file():
            return path
    return None


def varied_keys(spec: dict) -> list[str]:
    """The keys that tell the sweep's trials apart (as SweepSpec.varied)."""
    keys = list(spec.get("grid") or {}) + list(((spec.get("search") or {}).get("space")) or {})
    return keys + (["seed"] if len(spec.get("seeds", [0])) > 1 or not keys else [])


def _value(config: dict, key: str):
    head, _, tail = key.partition(".")
    value = config.get(head)
    return value.get(tail) if tail and isinstance(value, dict) else value


def _shown(value) -> str:
    if isinstance(value, float):
        return f"{value:.4g}"
    if isinstance(value, list):
        return ",".join(map(str, value))
    return str(value)


def _number(x: float, fmt: str) -> str:
    return "-" if x is None or (isinstance(x, float) and math.isnan(x)) else format(x, fmt)


def _state(info, sweep_dir: Path) -> str:
    """The registry's state, or "early-stopped" for a trial Ray Tune's scheduler stopped (its last result in
    _tune/experiment/<trial>/result.json is marked done without the trial having finished)."""
    if info.state != "stopped":
        return info.state
    try:
        lines = (sweep_dir / "_tune" / "experiment" / info.path.name / "result.json").read_text().splitlines()
        last = json.loads(lines[-1]) if lines else {}
    except (OSError, ValueError):
        return info.state
    return (
        "early-stopped" if last.get("done") and last.get("finished") is False and not last.get("stopped") else "stopped"
    )


def sweep_rows(sweep_dir: Path) -> tuple[dict, list[dict]]:
    """(the sweep's spec, one row per trial: its run info, settings, evaluation, target and `best` flag)."""
    spec = json.loads((sweep_dir / SWEEP_FILE).read_text())
    keys = varied_keys(spec)
    rows = []
    for info in list_runs(sweep_dir):
        config = json.loads((info.path / "config.json").read_text())
        rows.append({"info": info, "settings": {k: _value(config, k) for k in keys}, **trial_evaluation(info.path),
                     "target": read_json(info.path / TARGET_FILE)})  # fmt: skip
    best = best_of(rows, "eval_score", "max")
    for row in rows:
        row["best"] = row is best
    return spec, rows


def sweep_table(sweep_dir: Path) -> str:
    spec, rows = sweep_rows(sweep_dir)
    keys = varied_keys(spec)
    target = (spec.get("base") or {}).get("evaluation.target")
    head = ["", "TRIAL", *[k.split(".")[-1] for k in keys], "STATE", "STEPS", "WALL", "eval in band %",
            "energy %", "eval score", "at step", "target met at"]  # fmt: skip
    table = [head]
    for r in rows:
        info = r["info"]
        met = r["target"]
        table.append([
            "*" if r["best"] else "", info.path.name, *[_shown(r["settings"][k]) for k in keys],
            _state(info, sweep_dir),
            f"{info.steps}/{info.planned}" if info.planned else str(info.steps), duration(info.wall_s),
            _number(r["eval_in_band_pct"], ".2f"), _number(r["eval_energy_change_pct"], "+.2f"),
            _number(r["eval_score"], ".3f"), str(r["eval_timesteps"]) if r["eval_timesteps"] >= 0 else "-",
            f"{met['timesteps']} ({duration(met['wall_s'])})" if met else "-",
        ])  # fmt: skip
    widths = [max(len(row[i]) for row in table) for i in range(len(head))]
    lines = [f"sweep {spec['name']}  ({sweep_dir})  {len(rows)} trials"]
    if target:
        lines.append(f"target {target}: best = meets it, then lowest energy against the built-in controller")
    lines += [(row[0] or " ") + " " + "  ".join(c.ljust(w) for c, w in zip(row[1:], widths[1:], strict=True)).rstrip()
              for row in table]  # fmt: skip
    if not any(r["eval_score"] == r["eval_score"] for r in rows):
        lines.append("no evaluations: set [train.evaluation] every = STEPS in the sweep to rank its trials")
    elif any(r["best"] for r in rows):
        lines.append("* the best by evaluation (its best/model.zip); the configuration: best-command.txt, best.toml")
    return "\n".join(lines)
