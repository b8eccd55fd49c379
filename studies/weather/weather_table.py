"""Issue 40's tables and figures from `studies/weather/weather_study.sh evaluate` / `climates` (results/weather/).

For each building: every training variant (base, noise, forecast, both) on the five paper weathers, on noisy years
of them and on the 11 unseen climates: energy against the built-in controls and the comfort share, mean over seeds
(and noisy years) with a 95 % bootstrap interval (evaluation/seeds.py); how many of the 16 climates each variant
meets the issue's goal on; a figure of energy against comfort per variant. For the learned controllers of issue 29 on
all 16 climates: each climate's savings and comfort, how many keep the built-in's comfort at less energy, and a
bar figure of the savings by climate.

    .venv/bin/python studies/weather/weather_table.py results/weather
"""

from __future__ import annotations

import sys
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import pandas as pd  # noqa: E402

from parallel_eplus.evaluation.controllers import BASELINE_LABEL  # noqa: E402
from parallel_eplus.evaluation.seeds import interval, with_changes  # noqa: E402

SETS = {"paper": "five paper weathers", "noisy": "noisy years of them", "climates": "11 unseen climates"}


def _cell(values: list) -> str:
    point, low, high = interval(values)
    return f"{point:+.1f} %" if low != low else f"{point:+.1f} % [{low:+.1f}, {high:+.1f}]"


def _share(values: list) -> str:
    point, low, high = interval(values)
    return f"{point:.2f} %" if low != low else f"{point:.2f} % [{low:.2f}, {high:.2f}]"


def _results(out: Path, building: str, name: str) -> pd.DataFrame | None:
    path = out / building / name / "results.csv"
    return with_changes(pd.read_csv(path), BASELINE_LABEL) if path.is_file() else None


def variants_table(out: Path, building: str) -> list[str]:
    """One row per (variant, weather set): energy vs built-in and comfort, stratified over weathers; then each
    variant's count of climates (paper weathers and unseen ones) where it keeps the built-in's comfort at less
    energy, the issue's goal; and the frontier figure."""
    lines = [f"### {building}", "", "| variant | weathers | energy vs built-in | comfort: built-in → learned |",
             "| --- | --- | --- | --- |"]  # fmt: skip
    for name, what in SETS.items():
        df = _results(out, building, name)
        if df is None:
            continue
        base = df[df.controller == BASELINE_LABEL]
        base_comfort = _share([g.to_numpy() for _, g in base.groupby("weather")["in_band_pct"]])
        for variant, rows in df[df.controller != BASELINE_LABEL].groupby("controller", sort=False):
            energy = [g.to_numpy() for _, g in rows.groupby("weather")["energy_change_pct"]]
            comfort = [g.to_numpy() for _, g in rows.groupby("weather")["in_band_pct"]]
            lines.append(f"| {variant} | {what} | {_cell(energy)} | {base_comfort} → {_share(comfort)} |")
    lines += [""] + goal_counts(out, building) + frontier_figure(out, building)
    return lines


def goal_counts(out: Path, building: str) -> list[str]:
    """Per variant: on how many of the 16 climates (the five paper weathers and the 11 unseen, the same
    unperturbed years the climate tables use) its mean over seeds keeps at least the built-in's comfort at less
    energy."""
    frames = [df for name in ("paper", "climates") if (df := _results(out, building, name)) is not None]
    if not frames:
        return []
    df = pd.concat(frames)
    base = df[df.controller == BASELINE_LABEL].groupby("weather")["in_band_pct"].mean()
    lines = [
        "| variant | climates where it keeps the built-in's comfort at less energy | misses |",
        "| --- | --- | --- |",
    ]
    for variant, rows in df[df.controller != BASELINE_LABEL].groupby("controller", sort=False):
        mean = rows.groupby("weather", sort=False)[["energy_change_pct", "in_band_pct"]].mean()
        ok = (mean["energy_change_pct"] < 0) & (mean["in_band_pct"] >= mean.index.map(base))
        miss = mean[~ok]
        if len(miss) > 6:  # a range, not a list
            e, c = miss.energy_change_pct, miss.in_band_pct
            misses = f"{len(miss)}: {e.min():+.1f} to {e.max():+.1f} %, {c.min():.2f}-{c.max():.2f} % in band"
        else:
            misses = ", ".join(f"{w} ({m.energy_change_pct:+.1f} %, {m.in_band_pct:.2f} %)" for w, m in miss.iterrows())
        lines.append(f"| {variant} | {int(ok.sum())} of {len(ok)} | {misses or '–'} |")
    return lines + [""]


def frontier_figure(out: Path, building: str) -> list[str]:
    """Energy against comfort per weather set: each seed's mean over weathers (and noisy years) as a dot, the
    variant's mean over them as a larger mark, the built-in controls as a star."""
    sets = [(name, what, df) for name, what in SETS.items() if (df := _results(out, building, name)) is not None]
    if not sets:
        return []
    fig, axes = plt.subplots(1, len(sets), figsize=(4.2 * len(sets), 3.8), squeeze=False)
    for ax, (_, what, df) in zip(axes[0], sets, strict=True):
        base = df[df.controller == BASELINE_LABEL]
        ax.plot(0, base["in_band_pct"].mean(), "k*", markersize=12, label="built-in")
        for i, (variant, rows) in enumerate(df[df.controller != BASELINE_LABEL].groupby("controller", sort=False)):
            seed = rows["run"].fillna("").str.replace(r" year \d+$", "", regex=True)
            per_seed = rows.groupby(seed)[["energy_change_pct", "in_band_pct"]].mean()
            ax.plot(per_seed["energy_change_pct"], per_seed["in_band_pct"], "o", color=f"C{i}", alpha=0.45, ms=5)
            ax.plot(per_seed["energy_change_pct"].mean(), per_seed["in_band_pct"].mean(), "D", color=f"C{i}",
                    ms=8, markeredgecolor="k", label=variant)  # fmt: skip
        ax.set_title(what)
        ax.set_xlabel("energy vs built-in (%)")
        ax.grid(alpha=0.3)
    axes[0][0].set_ylabel("comfort: samples in band (%)")
    axes[0][-1].legend(fontsize=8, loc="best")
    fig.suptitle(f"{building}: training variants (dots: seeds; diamonds: their mean)")
    fig.tight_layout()
    fig.savefig(out / building / "variants.png", dpi=120)
    plt.close(fig)
    return [f"![{building}: energy against comfort per training variant]({building}/variants.png)", ""]


def climates_table(out: Path, building: str, folder: str = "climates") -> list[str]:
    """A building's learned controllers (`folder`: climates/ for issue 29's) on every climate: savings, comfort,
    the goal's count; writes a bar figure."""
    df = with_changes(pd.read_csv(out / folder / building / "results.csv"), BASELINE_LABEL)
    base = df[df.controller == BASELINE_LABEL].set_index("weather")
    learned = df[df.controller != BASELINE_LABEL]
    lines = [f"### {building}", "", "| climate | energy vs built-in | comfort: built-in → learned | goal |",
             "| --- | --- | --- | --- |"]  # fmt: skip
    met, bars = 0, []
    for weather, rows in learned.groupby("weather", sort=False):
        energy, comfort = interval([rows["energy_change_pct"]]), rows["in_band_pct"].mean()
        ok = energy[0] < 0 and comfort >= base.loc[weather, "in_band_pct"]
        met += ok
        bars.append((weather, *energy))
        lines.append(f"| {weather} | {_cell([rows['energy_change_pct']])} | {base.loc[weather, 'in_band_pct']:.2f} % "
                     f"→ {_share([rows['in_band_pct']])} | {'yes' if ok else 'no'} |")  # fmt: skip
    lines += ["", f"The built-in's comfort at less energy on **{met} of {len(bars)}** climates (goal: 14 of 16).", ""]
    fig, ax = plt.subplots(figsize=(9, 3.5))
    names = [b[0] for b in bars]
    mean = [-b[1] for b in bars]
    err = [[b[1] - b[2] if b[2] == b[2] else 0 for b in bars], [b[3] - b[1] if b[3] == b[3] else 0 for b in bars]]
    ax.bar(names, mean, yerr=[err[1], err[0]], color=["C0" if i < 5 else "C1" for i in range(len(names))], capsize=3)
    ax.set_ylabel("energy saved vs built-in (%)")
    ax.set_title(f"{building}: learned controller by climate (blue: paper weathers, orange: unseen)")
    ax.tick_params(axis="x", rotation=60)
    fig.tight_layout()
    fig.savefig(out / folder / f"{building}-savings.png", dpi=120)
    plt.close(fig)
    return lines + [f"![{building}: savings by climate]({folder}/{building}-savings.png)", ""]


# `weather_study.sh climates BUILDING RUNS LABEL` writes climates-LABEL/: whose controllers they are
CLIMATE_SETS = {"climates": "issue 29's learned controllers (clone, then RL)",
                "climates-model-based": "the model-based planner distilled into a policy (issue 38)",
                "climates-planner-january": "the model-based planner itself, January 1-14 (issue 38)"}  # fmt: skip


def main(out: Path) -> None:
    buildings = sorted(p.name for p in out.iterdir() if p.is_dir() and not p.name.startswith(("climates", "runs")))
    lines = ["# Weather noise, forecasts and every climate (issue 40)", "",
             "Written by `studies/weather/weather_table.py` from `studies/weather/weather_study.sh`'s evaluations; "
             "docs/weather.md explains the options. Mean over seeds (and noisy years) with a 95 % bootstrap "
             "interval.", "",
             "## Training variants", ""]  # fmt: skip
    for b in buildings:
        lines += variants_table(out, b)
    for folder in sorted(p.name for p in out.iterdir() if p.is_dir() and p.name.startswith("climates")):
        done = sorted(b.name for b in (out / folder).iterdir() if (b / "results.csv").is_file())
        if done:
            lines += [f"## Every climate the EnergyPlus wheel ships: {CLIMATE_SETS.get(folder, folder)}", ""]
            for b in done:
                lines += climates_table(out, b, folder)
    (out / "README.md").write_text("\n".join(lines))
    print(f"written: {out / 'README.md'}")


if __name__ == "__main__":
    main(Path(sys.argv[1] if len(sys.argv) > 1 else "results/weather"))
