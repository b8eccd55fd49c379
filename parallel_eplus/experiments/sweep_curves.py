"""`parallel-eplus plot runs/SWEEP`: learning curves of a sweep, one line per configuration averaged over its
seeds with a shaded interval, one panel per weather and metric.

The curves are the trials' evaluations (evaluations.csv: the frozen policy at the same steps in every seed) when
the trials evaluate, else their training episodes (episodes.csv, each seed's curve interpolated onto the steps
they share). The interval at each step is evaluation/seeds.py's: a 95 % percentile bootstrap of the mean over
the seeds. What it means for few seeds (docs/training.md): with n = 3 seeds every resample of three draws that
are all the lowest seed has probability 1/27 = 3.7 % > 2.5 %, so the interval's ends are exactly the seeds'
minimum and maximum: a range, not a 95 % confidence statement. n = 1 draws no band.
"""

from __future__ import annotations

import json
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402

from parallel_eplus.evaluation.seeds import interval  # noqa: E402
from parallel_eplus.experiments.sweep_view import SWEEP_FILE, varied_keys  # noqa: E402
from parallel_eplus.runs.registry import find_runs  # noqa: E402
from parallel_eplus.runs.run_files import ALL_WEATHERS, EVALUATIONS_FILE  # noqa: E402

EVAL_METRICS = {
    "reward_mean": "reward per step",
    "in_band_pct": "in band (%)",
    "energy_change_pct": "energy vs built-in (%)",
}
EPISODE_METRICS = {"reward_mean": "reward per step", "in_band_pct": "in band (%)"}
FIGURE = "learning-curves.png"


def _recipe(config: dict, keys: list[str]) -> str:
    """A configuration's label: its varied settings but the seed (its seeds are one recipe's runs)."""
    parts = []
    for key in (k for k in keys if k != "seed"):
        head, _, tail = key.partition(".")
        value = config.get(head)
        value = value.get(tail) if tail and isinstance(value, dict) else value
        parts.append(
            f"{key.split('.')[-1]}={value:.4g}" if isinstance(value, float) else f"{key.split('.')[-1]}={value}"
        )
    return ", ".join(parts) or "all seeds"


def curves(sweep_dir: Path) -> tuple[pd.DataFrame, str]:
    """Long table (recipe, seed, weather, timesteps, metric, value) and its source ("evaluations"/"episodes")."""
    spec = json.loads((sweep_dir / SWEEP_FILE).read_text())
    keys = varied_keys(spec)
    runs = find_runs(sweep_dir)
    evaluated = runs and all((r / EVALUATIONS_FILE).is_file() for r in runs)
    frames = []
    for run in runs:
        config = json.loads((run / "config.json").read_text())
        if evaluated:
            df = pd.read_csv(run / EVALUATIONS_FILE)
            df = df[df["weather"] != ALL_WEATHERS]
            metrics = [m for m in EVAL_METRICS if m in df]
        elif (run / "episodes.csv").is_file():
            df = pd.read_csv(run / "episodes.csv")
            metrics = [m for m in EPISODE_METRICS if m in df]
        else:
            continue
        long = df.melt(id_vars=["weather", "timesteps"], value_vars=metrics, var_name="metric")
        frames.append(long.assign(recipe=_recipe(config, keys), seed=config.get("seed", 0), run=run.name))
    if not frames:
        raise FileNotFoundError(f"{sweep_dir}: no trial has evaluations.csv or episodes.csv yet")
    return pd.concat(frames, ignore_index=True), "evaluations" if evaluated else "episodes"


def _band(group: pd.DataFrame) -> pd.DataFrame:
    """Mean over the seeds with its interval, at the steps all of them reached (interpolated per seed)."""
    per_run = {r: g.groupby("timesteps")["value"].mean() for r, g in group.groupby("run")}
    end = min(s.index.max() for s in per_run.values())
    steps = np.unique(np.concatenate([s.index[s.index <= end] for s in per_run.values()]))
    values = np.array([np.interp(steps, s.index, s.to_numpy()) for s in per_run.values()])
    rows = []
    for i, step in enumerate(steps):
        mean, low, high = interval([values[:, i]])
        rows.append({"timesteps": step, "mean": mean, "low": low, "high": high, "seeds": len(values)})
    return pd.DataFrame(rows)


def plot_sweep(sweep_dir: Path) -> Path:
    """runs/<sweep>/learning-curves.png."""
    sweep_dir = Path(sweep_dir)
    data, source = curves(sweep_dir)
    weathers = list(dict.fromkeys(data["weather"]))
    metrics = list(dict.fromkeys(data["metric"]))
    names = EVAL_METRICS if source == "evaluations" else EPISODE_METRICS
    fig, axes = plt.subplots(len(metrics), len(weathers), figsize=(max(7.0, 4.5 * len(weathers)), 2.8 * len(metrics)),
                             squeeze=False, sharex=True, layout="constrained")  # fmt: skip
    colors = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    for k, (recipe, group) in enumerate(data.groupby("recipe", sort=False)):
        color = colors[k % len(colors)]
        for i, metric in enumerate(metrics):
            for j, weather in enumerate(weathers):
                g = group[(group["metric"] == metric) & (group["weather"] == weather)].dropna(subset=["value"])
                if g.empty:
                    continue
                band = _band(g)
                ax = axes[i][j]
                n = int(band["seeds"].max())
                ax.plot(band["timesteps"], band["mean"], "o-", ms=3, color=color,
                        label=f"{recipe} (n={n})" if i == j == 0 else None)  # fmt: skip
                if n > 1:
                    ax.fill_between(band["timesteps"], band["low"], band["high"], color=color, alpha=0.2, lw=0)
    for i, metric in enumerate(metrics):
        axes[i][0].set_ylabel(names.get(metric, metric))
    for j, weather in enumerate(weathers):
        axes[0][j].set_title(f"{weather} ({'evaluation' if source == 'evaluations' else 'training episodes'})",
                             fontsize=9)  # fmt: skip
        axes[-1][j].set_xlabel("timesteps")
    title = "mean over seeds; band: 95 % percentile bootstrap (n=3: the seeds' min-max)"
    fig.legend(loc="outside lower center", fontsize=8, ncols=1, title=title, title_fontsize=8)
    fig.suptitle(f"sweep {sweep_dir.name}", fontsize=10)
    path = sweep_dir / FIGURE
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path
