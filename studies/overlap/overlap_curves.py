"""Learning with and without `train --overlap`: in-band share and power against steps, batch by batch.

Reads runs named `<prefix>-off-s<seed>` and `<prefix>-on-s<seed>` (the same settings and seed, without and with
--overlap) from --runs, trained with --keep-episodes at least their episodes per worker. From each worker's step
tables it computes, per batch of the worker's own steps, the share of zone samples in band and the mean power.
Same seed, same weather cycle and full-year episodes from Jan 1: worker i's k-th batch covers the same days of
the same weather in both runs, so batches are compared in pairs. Writes overlap_curves.png and overlap_curves.md
(the pairs' differences, per batch and overall, and each run's speed and idle shares) to --out.

    PYTHONPATH=. .venv/bin/python studies/overlap/overlap_curves.py --runs /tmp/ovc/runs \
        --tb /tmp/ovc/tensorboard_logs --out results/overlap
"""

from __future__ import annotations

import argparse
import json
import re
import statistics
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402
from tensorboard.backend.event_processing.event_accumulator import EventAccumulator  # noqa: E402

from parallel_eplus.buildings.building import load_building  # noqa: E402
from parallel_eplus.engine.episode import read_steps  # noqa: E402

METRICS = {"in_band_pct": "zone samples in 22–25 °C (%)", "power_kw": "average power (kW)"}
COLOURS = {"off": "tab:blue", "on": "tab:orange"}
NAMES = {"off": "sequential", "on": "overlap"}


def batches_of(run: Path) -> pd.DataFrame:
    """One row per (worker, batch of the worker's steps): in-band share and power over the batch's steps."""
    cfg = json.loads((run / "config.json").read_text())
    per_worker = -(-cfg["batch_size"] // cfg["workers"])
    comfort = load_building(cfg.get("building")).comfort
    low, high = comfort.band
    rows = []
    for w in range(cfg["workers"]):
        episodes = sorted((run / "episodes" / f"worker-{w}").glob("episode-*"), key=lambda d: d.name)
        tables = [read_steps(d) for d in episodes if (d / "steps.parquet").is_file()]
        if not tables:
            continue
        steps = pd.concat(tables, ignore_index=True)
        power = steps["power_w"].to_numpy() / 1e3
        temps = steps[list(comfort.temperatures)].to_numpy()
        ok = ((temps >= low) & (temps <= high)).mean(axis=1)
        for k in range(len(steps) // per_worker):
            sl = slice(k * per_worker, (k + 1) * per_worker)
            rows.append({"worker": w, "batch": k + 1, "steps": (k + 1) * per_worker * cfg["workers"],
                         "in_band_pct": 100 * ok[sl].mean(), "power_kw": power[sl].mean()})  # fmt: skip
    return pd.DataFrame(rows)


def _speed(tb: Path) -> dict[str, float]:
    ea = EventAccumulator(str(tb), size_guidance={"scalars": 0})
    ea.Reload()
    tags = ea.Tags()["scalars"]

    def values(tag: str) -> list[float]:
        return [e.value for e in ea.Scalars(tag)] if tag in tags else [float("nan")]

    return {
        "steps_per_s": values("throughput/env_steps_per_s")[-1],
        "update_s": statistics.median(values("throughput/update_s")),
        "learner_idle": statistics.mean(values("throughput/learner_idle_share")[1:] or [float("nan")]),
        "workers_idle": statistics.mean(values("throughput/workers_idle_share")[1:] or [float("nan")]),
    }


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--runs", type=Path, required=True)
    p.add_argument("--tb", type=Path, required=True)
    p.add_argument("--prefix", default="curve")
    p.add_argument("--out", type=Path, required=True)
    args = p.parse_args()
    runs = {}
    for d in sorted(args.runs.glob(f"{args.prefix}-*-s*")):
        m = re.fullmatch(rf"{re.escape(args.prefix)}-(off|on)-s(\d+)", d.name)
        if m and not (df := batches_of(d)).empty:  # a run with no finished episode has nothing to show yet
            runs[(m[1], int(m[2]))] = df
    seeds = sorted({s for _, s in runs})
    args.out.mkdir(parents=True, exist_ok=True)

    fig, axes = plt.subplots(1, 2, figsize=(11, 4), constrained_layout=True)
    for ax, (metric, label) in zip(axes, METRICS.items(), strict=True):
        for (mode, seed), df in sorted(runs.items()):
            mean = df.groupby("steps")[metric].mean()  # over the workers (their weathers differ)
            ax.plot(mean.index, mean.values, marker="o", ms=3, lw=1.2, color=COLOURS[mode],
                    ls="-" if seed == seeds[0] else "--", label=f"{NAMES[mode]}, seed {seed}")  # fmt: skip
        ax.set_xlabel("env steps (end of the batch)")
        ax.set_ylabel(label)
        ax.grid(alpha=0.3)
    axes[0].legend(fontsize=8)
    fig.suptitle("TRPO, CA-CO-FL, 2 workers, full-year episodes: each batch's steps, mean over the 2 workers")
    fig.savefig(args.out / "overlap_curves.png", dpi=120)

    pairs = []
    for seed in seeds:
        if ("off", seed) in runs and ("on", seed) in runs:
            both = runs[("off", seed)].merge(
                runs[("on", seed)], on=["worker", "batch", "steps"], suffixes=("_off", "_on")
            )
            pairs.append(both.assign(seed=seed))
    lines = ["| batch (steps) | in band: sequential → overlap (pairs' mean) | power kW: sequential → overlap | pairs |",
             "|---|---|---|---|"]  # fmt: skip
    summary = []
    if pairs:
        both = pd.concat(pairs)
        for (batch, steps), g in both.groupby(["batch", "steps"]):
            band = f"{g['in_band_pct_off'].mean():.1f} → {g['in_band_pct_on'].mean():.1f} %"
            power = f"{g['power_kw_off'].mean():.1f} → {g['power_kw_on'].mean():.1f}"
            lines.append(f"| {batch} ({steps:,}) | {band} | {power} | {len(g)} |")
        for metric, unit in (("in_band_pct", "points"), ("power_kw", "kW")):
            d = both[f"{metric}_on"] - both[f"{metric}_off"]
            half = both["batch"] > both["batch"].max() / 2
            lo, hi = np.percentile(
                [d.sample(len(d), replace=True, random_state=i).mean() for i in range(2000)], [2.5, 97.5]
            )
            summary.append(f"- {metric}: overlap minus sequential over {len(d)} (seed, worker, batch) pairs: mean "
                           f"{d.mean():+.2f} {unit} (bootstrap 95 % interval {lo:+.2f} to {hi:+.2f}); second half of "
                           f"the budget {d[half].mean():+.2f} {unit}")  # fmt: skip
    speed = ["", "| run | steps/s | update s (median) | learner idle | workers idle |", "|---|---|---|---|---|"]
    for mode, seed in sorted(runs):
        s = _speed(args.tb / f"{args.prefix}-{mode}-s{seed}")
        speed.append(f"| {NAMES[mode]}, seed {seed} | {s['steps_per_s']:.0f} | {s['update_s']:.1f} | "
                     f"{s['learner_idle']:.2f} | {s['workers_idle']:.3f} |")  # fmt: skip
    text = "\n".join([*lines, "", *summary, *speed]) + "\n"
    (args.out / "overlap_curves.md").write_text(text)
    print(text)


if __name__ == "__main__":
    main()
