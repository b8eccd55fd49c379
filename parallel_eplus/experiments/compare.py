"""Which algorithm learns the building fastest: TRPO, PPO and SAC on one budget, evaluated along the way.

Each algorithm trains in resumable chunks (`train --resume`); after every chunk its model is evaluated
frozen and deterministic on all five weathers (`sweep.run_sweep`). Progress lives in `<out>/progress.csv`,
so a rerun skips finished chunks. `compare_figure` and `compare_table` draw the result against the
built-in and rule-based controllers' rows of an existing results.csv.
"""

from __future__ import annotations

import logging
import time
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import pandas as pd  # noqa: E402

from parallel_eplus.evaluation.controllers import BASELINE_LABEL, RBC_LABEL, policy_controller
from parallel_eplus.evaluation.plots import controller_colors  # noqa: E402
from parallel_eplus.evaluation.seeds import interval  # noqa: E402
from parallel_eplus.evaluation.sweep import run_sweep  # noqa: E402
from parallel_eplus.runs.run_files import saved_steps  # noqa: E402
from parallel_eplus.training.config import TrainConfig  # noqa: E402
from parallel_eplus.training.train import train  # noqa: E402

log = logging.getLogger(__name__)

ALL_WEATHERS = ["CA", "CO", "FL", "IL", "VA"]


def run_comparison(
    out: Path, algorithms: list[str], timesteps: int, eval_every: int, base: TrainConfig, eval_days: int = 365,
    seeds: list[int] | None = None,
) -> pd.DataFrame:  # fmt: skip
    """Train each algorithm (with each seed) to `timesteps` in chunks of `eval_every`, evaluating after each;
    returns progress. One seed keeps the run folder named after the algorithm, as before seeds were asked for."""
    seeds = seeds or [base.seed]
    progress_csv = out / "progress.csv"
    done = pd.read_csv(progress_csv) if progress_csv.is_file() else pd.DataFrame(columns=["algorithm", "target"])
    if "seed" not in done.columns:  # a comparison from before seeds: its runs used the default seed
        done["seed"] = base.seed
    for algorithm in algorithms:
        for seed in seeds:
            done = _compare_one(out, algorithm, seed, len(seeds) > 1, timesteps, eval_every, base, eval_days, done)
    return done


def _compare_one(out, algorithm, seed, named_by_seed, timesteps, eval_every, base, eval_days, done) -> pd.DataFrame:
    name = f"{algorithm}-seed{seed}" if named_by_seed else algorithm
    run_dir = out / "runs" / name
    mine = (done["algorithm"] == algorithm) & (done["seed"] == seed)
    wall = float(done.loc[mine, "wall_s"].max()) if mine.any() else 0.0
    wall = 0.0 if pd.isna(wall) else wall
    for target in range(eval_every, timesteps + eval_every, eval_every):
        target = min(target, timesteps)
        if (mine & (done["target"] == target)).any():
            continue
        t0 = time.monotonic()
        if (run_dir / "config.json").is_file():
            final = train(TrainConfig(timesteps=target), resume=run_dir, progress=True)
        else:
            cfg = TrainConfig(**{**vars(base), "algorithm": algorithm, "timesteps": target, "run_name": name,
                                 "seed": seed, "runs_dir": str(out / "runs"),
                                 "checkpoint_every": eval_every})  # fmt: skip
            final = train(cfg, progress=True)
        wall += time.monotonic() - t0
        steps = saved_steps(final)
        controller = policy_controller(str(final))
        df = run_sweep([controller], ALL_WEATHERS, eval_days, base.workers, out / "eval" / f"{name}-{steps}")
        row = {"algorithm": algorithm, "seed": seed, "target": target, "steps": steps, "wall_s": wall,
               "in_band_pct": df["in_band_pct"].mean(), "power_kw": df["power_kw"].mean(),
               "reward_mean": df["reward_mean"].mean()}  # fmt: skip
        done = pd.concat([done, pd.DataFrame([row])], ignore_index=True)
        out.mkdir(parents=True, exist_ok=True)
        done.to_csv(out / "progress.csv", index=False)
        log.info("%s at %d steps (%.1f h): %.1f %% in band, %.1f kW", name, steps, wall / 3600,
                 row["in_band_pct"], row["power_kw"])  # fmt: skip
    return done


def references(results_csv: Path) -> dict[str, tuple[float, float, float]]:
    """The built-in and rule-based controllers' five-weather means: label -> (in-band %, power kW, reward/step)."""
    df = pd.read_csv(results_csv)
    df = df[df["weather"].isin(ALL_WEATHERS)]
    return {
        label: (g["in_band_pct"].mean(), g["power_kw"].mean(), g["reward_mean"].mean())
        for label, g in df.groupby("controller")
        if label in (BASELINE_LABEL, RBC_LABEL)
    }


def draw_comparison(progress: pd.DataFrame, refs: dict[str, tuple[float, float, float]]) -> plt.Figure:
    """In-band % and power saved (against the built-in controller) vs. env steps and vs. wall time.

    The references are lines in their colours of every other figure (`plots.REFERENCE_COLORS`); the legend
    sits outside the axes so no curve hides behind it.
    """
    baseline_kw = refs[BASELINE_LABEL][1]
    labels = [a.upper() for a in dict.fromkeys(progress["algorithm"])]
    colors = controller_colors([*refs, *labels])
    fig, axes = plt.subplots(2, 2, figsize=(11, 7), sharey="row", layout="constrained")
    for algorithm, g in progress.groupby("algorithm", sort=False):
        g = g.assign(saved=100 * (baseline_kw - g["power_kw"]) / baseline_kw, hours=g["wall_s"] / 3600)
        by = g.groupby("target")  # across seeds: the mean, and the 95 % interval shaded where there are several
        style = {"marker": "o", "label": algorithm.upper(), "color": colors[algorithm.upper()]}
        for col, x in enumerate((by["steps"].mean(), by["hours"].mean())):
            for row, metric in enumerate(("in_band_pct", "saved")):
                axes[row, col].plot(x, by[metric].mean(), **style)
                bounds = [interval([v.to_numpy()])[1:] for _, v in by[metric]]
                low, high = (list(b) for b in zip(*bounds, strict=True))
                if not pd.isna(low).all():
                    axes[row, col].fill_between(x, low, high, color=style["color"], alpha=0.2, lw=0)
    for label, (in_band, kw, _) in refs.items():
        style = {"color": colors[label], "linestyle": ":" if label == BASELINE_LABEL else "--", "linewidth": 1,
                 "label": label}  # fmt: skip
        for col in range(2):
            axes[0, col].axhline(in_band, **style)
            axes[1, col].axhline(100 * (baseline_kw - kw) / baseline_kw, **style)
    for col, xlabel in enumerate(("environment steps", "wall time (h)")):
        axes[1, col].set_xlabel(xlabel)
    axes[0, 0].set_ylabel("zone samples in 22-25 °C (%)")
    axes[1, 0].set_ylabel("power saved vs. built-in (%)")
    fig.legend(*axes[0, 0].get_legend_handles_labels(), loc="outside right upper", fontsize=8)
    fig.suptitle(f"{', '.join(labels)} on CA-CO-FL: five-weather mean, frozen deterministic policy", fontsize=10)
    return fig


def compare_figure(progress: pd.DataFrame, refs: dict[str, tuple[float, float, float]], path: Path) -> Path:
    """`draw_comparison`, saved to `path`."""
    fig = draw_comparison(progress, refs)
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path


def _across_seeds(values, digits: int) -> str:
    mean, low, high = interval([values])
    return f"{mean:.{digits}f}" if len(values) < 2 else f"{mean:.{digits}f} [{low:.{digits}f}, {high:.{digits}f}]"


def compare_table(progress: pd.DataFrame, refs: dict[str, tuple[float, float, float]]) -> str:
    """Markdown: each algorithm's last evaluation beside the reference controllers."""
    baseline_kw = refs[BASELINE_LABEL][1]
    lines = ["| controller | env steps | wall time (h) | in 22-25 °C (%) | power (kW) | power saved (%) "
             "| reward per step |", "|---|---:|---:|---:|---:|---:|---:|"]  # fmt: skip
    for label, (in_band, kw, reward) in refs.items():
        lines.append(f"| {label} | - | - | {in_band:.2f} | {kw:.2f} | {100 * (baseline_kw - kw) / baseline_kw:.1f} "
                     f"| {reward:.2f} |")  # fmt: skip
    for algorithm, g in progress.groupby("algorithm", sort=False):
        last = g.sort_values("steps").groupby("seed" if "seed" in g else "algorithm").tail(1)
        last = last.assign(saved=100 * (baseline_kw - last["power_kw"]) / baseline_kw)
        cells = [_across_seeds(last[m].to_numpy(), d) for m, d in
                 (("in_band_pct", 2), ("power_kw", 2), ("saved", 1), ("reward_mean", 2))]  # fmt: skip
        label = algorithm.upper() + (f" ({len(last)} seeds)" if len(last) > 1 else "")
        lines.append(f"| {label} | {int(last.steps.mean()):,} | {last.wall_s.mean() / 3600:.2f} | "
                     + " | ".join(cells) + " |")  # fmt: skip
    if "seed" in progress and progress.groupby("algorithm")["seed"].nunique().max() > 1:
        lines.append("\nSeveral seeds: their mean with a 95 % percentile bootstrap interval (evaluation/seeds.py).")
    return "\n".join(lines) + "\n"
