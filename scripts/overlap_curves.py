"""Learning with and without `train --overlap`: in-band share and power of every training episode against steps.

Reads runs named `<prefix>-off-s<seed>` and `<prefix>-on-s<seed>` (the same settings and seed, without and with
--overlap) from --runs, and their TensorBoard folders from --tb. Same seed, same weather cycle: worker i's
episode k has the same weather in both runs, so episodes are compared in pairs. Writes overlap_curves.png and
overlap_curves.md (the pairs, their mean difference, and each run's speed and idle shares) to --out.

    PYTHONPATH=. .venv/bin/python scripts/overlap_curves.py --runs /tmp/ovc/runs --tb /tmp/ovc/tensorboard_logs \
        --out results/overlap
"""

from __future__ import annotations

import argparse
import re
import statistics
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import pandas as pd  # noqa: E402
from tensorboard.backend.event_processing.event_accumulator import EventAccumulator  # noqa: E402

METRICS = {"in_band_pct": "zone samples in 22–25 °C (%)", "power_kw": "average power (kW)"}
COLOURS = {"off": "tab:blue", "on": "tab:orange"}


def _runs(root: Path, prefix: str) -> dict[tuple[str, int], pd.DataFrame]:
    out = {}
    for d in sorted(root.glob(f"{prefix}-*-s*")):
        m = re.fullmatch(rf"{re.escape(prefix)}-(off|on)-s(\d+)", d.name)
        if m and (d / "episodes.csv").is_file():
            out[(m[1], int(m[2]))] = pd.read_csv(d / "episodes.csv")
    return out


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
    runs = _runs(args.runs, args.prefix)
    seeds = sorted({s for _, s in runs})
    args.out.mkdir(parents=True, exist_ok=True)

    fig, axes = plt.subplots(1, 2, figsize=(11, 4), constrained_layout=True)
    for ax, (metric, label) in zip(axes, METRICS.items(), strict=True):
        for (mode, seed), df in sorted(runs.items()):
            for worker, part in df.groupby("worker"):
                name = f"{'overlap' if mode == 'on' else 'sequential'}, seed {seed}"
                ax.plot(part["timesteps"], part[metric], marker="o", ms=3, lw=1, color=COLOURS[mode],
                        ls="-" if seed == seeds[0] else "--", label=name if worker == 0 else None)  # fmt: skip
        ax.set_xlabel("env steps")
        ax.set_ylabel(label)
        ax.grid(alpha=0.3)
    axes[0].legend(fontsize=8)
    fig.suptitle("TRPO, CA-CO-FL, 2 workers, full-year episodes: every training episode, per worker")
    fig.savefig(args.out / "overlap_curves.png", dpi=120)

    lines = ["| seed | worker | episode | weather | in band: sequential → overlap | power kW: sequential → overlap |",
             "|---|---|---|---|---|---|"]  # fmt: skip
    diffs: dict[str, list[float]] = {m: [] for m in METRICS}
    for seed in seeds:
        off, on = runs.get(("off", seed)), runs.get(("on", seed))
        if off is None or on is None:
            continue
        pairs = off.merge(on, on=["worker", "episode"], suffixes=("_off", "_on"))
        for _, r in pairs.sort_values(["episode", "worker"]).iterrows():
            assert r["weather_off"] == r["weather_on"], "the same seed cycles the same weathers"
            for m in METRICS:
                diffs[m].append(r[f"{m}_on"] - r[f"{m}_off"])
            lines.append(f"| {seed} | {r['worker']} | {r['episode']} | {r['weather_off']} | "
                         f"{r['in_band_pct_off']:.1f} → {r['in_band_pct_on']:.1f} % | "
                         f"{r['power_kw_off']:.1f} → {r['power_kw_on']:.1f} |")  # fmt: skip
    summary = []
    if diffs["power_kw"]:
        band, power = diffs["in_band_pct"], diffs["power_kw"]
        summary.append(f"- {len(power)} episode pairs; overlap minus sequential, mean (min, max): in band "
                       f"{statistics.mean(band):+.1f} points ({min(band):+.1f}, {max(band):+.1f}); power "
                       f"{statistics.mean(power):+.1f} kW ({min(power):+.1f}, {max(power):+.1f})")  # fmt: skip
    speed = ["", "| run | steps/s | update s (median) | learner idle | workers idle |", "|---|---|---|---|---|"]
    for mode, seed in sorted(runs):
        s = _speed(args.tb / f"{args.prefix}-{mode}-s{seed}")
        speed.append(f"| {mode}, seed {seed} | {s['steps_per_s']:.0f} | {s['update_s']:.1f} | "
                     f"{s['learner_idle']:.2f} | {s['workers_idle']:.3f} |")  # fmt: skip
    text = "\n".join([*lines, "", *summary, *speed]) + "\n"
    (args.out / "overlap_curves.md").write_text(text)
    print(text)


if __name__ == "__main__":
    main()
