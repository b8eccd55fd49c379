"""Issue 40's tables and figures from `scripts/weather_study.sh evaluate` / `climates` (results/weather/).

For each building: every training variant (base, noise, forecast, both) on the five paper weathers, on noisy years
of them and on the 11 unseen climates: energy against the built-in controls and the comfort share, mean over seeds
(and noisy years) with a 95 % bootstrap interval (evaluation/seeds.py). For the learned controllers of issue 29 on
all 16 climates: each climate's savings and comfort, how many keep the built-in's comfort at less energy, and a
bar figure of the savings by climate.

    .venv/bin/python scripts/weather_table.py results/weather
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


def variants_table(out: Path, building: str) -> list[str]:
    """One row per (variant, weather set): energy vs built-in and comfort, stratified over weathers."""
    lines = [f"### {building}", "", "| variant | weathers | energy vs built-in | comfort: built-in → learned |",
             "| --- | --- | --- | --- |"]  # fmt: skip
    for name, what in SETS.items():
        path = out / building / name / "results.csv"
        if not path.is_file():
            continue
        df = with_changes(pd.read_csv(path), BASELINE_LABEL)
        base = df[df.controller == BASELINE_LABEL]
        base_comfort = _share([g.to_numpy() for _, g in base.groupby("weather")["in_band_pct"]])
        for variant, rows in df[df.controller != BASELINE_LABEL].groupby("controller", sort=False):
            energy = [g.to_numpy() for _, g in rows.groupby("weather")["energy_change_pct"]]
            comfort = [g.to_numpy() for _, g in rows.groupby("weather")["in_band_pct"]]
            lines.append(f"| {variant} | {what} | {_cell(energy)} | {base_comfort} → {_share(comfort)} |")
    return lines + [""]


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
             "Written by `scripts/weather_table.py` from `scripts/weather_study.sh`'s evaluations; docs/weather.md "
             "explains the options. Mean over seeds (and noisy years) with a 95 % bootstrap interval.", "",
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
