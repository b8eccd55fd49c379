"""The report's two figures, drawn from the files beside it: savings against discomfort (one point per candidate, from
the held-out and the training figures), and a typical day of zone temperatures and setpoints under the own controls
and the chosen controller (from their evaluations' step records, as `parallel-eplus plot` reads an episode)."""

from __future__ import annotations

from pathlib import Path

import pandas as pd

from parallel_eplus.optimize.candidates import OWN
from parallel_eplus.optimize.choice import KH_ALLOWANCE, METRIC_NAMES, MIN_SAVING
from parallel_eplus.optimize.settings import QUICK

SAVINGS_PNG = "savings.png"
DAY_PNG = "typical-day.png"


def _pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def savings(train: pd.DataFrame, held: pd.DataFrame, metric: str, path: Path) -> Path:
    """x: the metric against the own controls' (%), y: occupied K·h against theirs; filled: held-out, hollow:
    training; the choice's limits dashed."""
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(7, 4.5), layout="constrained")
    for df, filled, where in ((held, True, "held-out"), (train, False, "training")):
        if df.empty or f"{metric}_x" not in df:
            continue
        for i, (_, r) in enumerate(df.iterrows()):
            color = f"C{i}"
            x, y = 100 * (r[f"{metric}_x"] - 1), r.kh - r.kh_own
            ax.scatter([x], [y], s=60, color=color if filled else "none", edgecolors=color,
                       label=f"{r.label} ({where})")  # fmt: skip
    ax.axvline(-100 * MIN_SAVING, color="grey", ls="--", lw=0.8)
    ax.axhline(KH_ALLOWANCE, color="grey", ls="--", lw=0.8)
    ax.axvline(0, color="black", lw=0.5)
    ax.axhline(0, color="black", lw=0.5)
    ax.set_xlabel(f"{METRIC_NAMES[metric]} against the own controls (%)")
    ax.set_ylabel("occupied discomfort against the own controls (K·h)")
    ax.set_title("Savings against discomfort: choose left of and below the dashed lines", fontsize=10)
    ax.legend(fontsize=7, loc="best")
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path


def _day(steps: pd.DataFrame, day_of_year: int) -> pd.DataFrame:
    t = pd.to_datetime(steps["time"]) - pd.Timedelta(seconds=1)  # each step in the day it belongs to
    return steps[t.dt.dayofyear == day_of_year].assign(time=pd.to_datetime(steps["time"]))


def typical_day(results: pd.DataFrame, spec: Path, shown: list[tuple[str, str]], period: str, weather: str,
                day: int, path: Path) -> Path | None:  # fmt: skip
    """One panel per (candidate, label) in `shown`: each zone's temperature, its own bounds (shaded), and the
    controller's setpoints where it sets them (dashed), on day `day` (0: January 1) of `period` on `weather`."""
    from parallel_eplus.buildings.building import load_building
    from parallel_eplus.engine.episode import read_steps

    building = load_building(str(spec))
    rows = results[(results.period == period) & (results.weather == weather)]
    panels = []
    for key, label in shown:
        mine = rows[rows.candidate == key]
        if mine.empty or not Path(mine.episode_dir.iloc[0]).is_dir():
            continue
        steps = _day(read_steps(mine.episode_dir.iloc[0]), day + 1)
        if not steps.empty:
            panels.append((label, steps))
    if not panels:
        return None
    plt = _pyplot()
    fig, axes = plt.subplots(len(panels), 1, figsize=(10, 3.2 * len(panels)), sharex=True, sharey=True,
                             layout="constrained", squeeze=False)  # fmt: skip
    setpoints = [a.name for a in building.spec.actions if a.name.endswith("_c")]
    for ax, (label, steps) in zip(axes[:, 0], panels, strict=True):
        for i, zone in enumerate(building.temperatures):
            ax.plot(steps.time, steps[zone], lw=0.9, color=f"C{i}", label=zone.removesuffix("_c").removesuffix("_temp"))
        if building.comfort.per_step:
            for lo, hi in dict.fromkeys(building.comfort.bound_names):
                ax.fill_between(steps.time, steps[lo], steps[hi], step="pre", color="green", alpha=0.1, lw=0)
        else:
            ax.axhspan(*building.band, color="green", alpha=0.1)
        for j, name in enumerate(c for c in setpoints if c in steps):
            ax.plot(steps.time, steps[name], lw=1.0, ls="--", color=f"C{len(building.temperatures) + j}", label=name)
        ax.set_ylabel("°C")
        ax.set_title(f"{label}: zones, own bounds (green), its setpoints (dashed)", fontsize=9)
        ax.legend(loc="upper left", bbox_to_anchor=(1.0, 1.0), fontsize=7)
    kind = {"peak_heat": "peak heating", "typical_heat": "typical heating", "peak_cool": "peak cooling",
            "typical_cool": "typical cooling"}.get(period, period)  # fmt: skip
    what = "the quick window's first day" if period == QUICK else f"BOPTEST's {kind} day"
    fig.suptitle(f"{weather}, {panels[0][1].time.iloc[0]:%b %d}: {what}", fontsize=10)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def day_shown(chosen: str, chosen_label: str, held: pd.DataFrame, metric: str) -> list[tuple[str, str]]:
    """The own controls and the chosen controller; when the own controls are chosen, beside the candidate with the
    lowest held-out figure (not chosen), so the figure shows what it would have done."""
    shown = [(OWN, "own controls")]
    if chosen != OWN:
        return shown + [(chosen, f"{chosen_label} (chosen)")]
    others = held[held.candidate != OWN] if not held.empty else held
    if not others.empty and f"{metric}_x" in others:
        best = others.sort_values(f"{metric}_x").iloc[0]
        shown.append((best.candidate, f"{best.label} (not chosen)"))
    return shown
