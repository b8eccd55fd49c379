"""Figures: the paper's Figures 3 and 4, power per controller, and one episode as time series."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402

from parallel_eplus.buildings.model import COMFORT_BAND_C  # noqa: E402
from parallel_eplus.engine.episode import STEPS_FILE, SUMMARY_FILE, read_steps, summarize  # noqa: E402


def _save(fig, path: Path) -> Path:
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path


def temperature_comparison(df: pd.DataFrame, path: Path) -> Path:
    """Figure 4 left: per controller, weather and zone a min-max line with a mean +- std box."""
    controllers = list(dict.fromkeys(df["controller"]))
    weathers = list(dict.fromkeys(df["weather"]))
    fig, ax = plt.subplots(figsize=(max(6, 1.2 * len(controllers) * len(weathers)), 4))
    x, ticks, labels = 0.0, [], []
    for c in controllers:
        for w in weathers:
            r = df[(df.controller == c) & (df.weather == w)]
            if r.empty:
                continue
            r = r.iloc[0]
            for k, (zone, color) in enumerate((("west", "tab:blue"), ("east", "tab:orange"))):
                xi = x + (k - 0.5) * 0.35
                ax.vlines(xi, r[f"{zone}_temp_min"], r[f"{zone}_temp_max"], color=color, lw=1)
                mean, std = r[f"{zone}_temp_mean"], r[f"{zone}_temp_std"]
                ax.add_patch(plt.Rectangle((xi - 0.12, mean - std), 0.24, 2 * std, color=color, alpha=0.8))
            ticks.append(x)
            labels.append(f"{w}")
            x += 1
        x += 0.6
    ax.axhspan(*COMFORT_BAND_C, color="green", alpha=0.08, label="22–25 °C")
    ax.set_xticks(ticks, labels)
    ax.set_ylabel("zone temperature (°C)")
    ax.set_title("Zone temperatures: min–max line, mean ± std box (West blue, East orange)")
    # Controller names under their group of weathers.
    group = len(weathers)
    for i, c in enumerate(controllers):
        ax.annotate(c, xy=(i * (group + 0.6) + (group - 1) / 2, 0), xycoords=("data", "axes fraction"),
                    xytext=(0, -28), textcoords="offset points", ha="center", fontsize=9)  # fmt: skip
    return _save(fig, path)


def power_comparison(df: pd.DataFrame, path: Path) -> Path:
    """Average total power per controller and weather."""
    table = df.pivot(index="weather", columns="controller", values="power_kw")
    table = table.loc[list(dict.fromkeys(df["weather"])), list(dict.fromkeys(df["controller"]))]
    fig, ax = plt.subplots(figsize=(7, 4))
    table.plot.bar(ax=ax, rot=0)
    ax.set_ylabel("average total power (kW)")
    ax.set_xlabel("test weather")
    ax.set_title("Average power per controller and weather")
    return _save(fig, path)


def west_zone_histogram(episode_dir: Path, title: tuple[str, str], path: Path) -> Path:
    """Figure 4 right: distribution of West-zone temperatures for one controller and weather."""
    steps = read_steps(episode_dir)
    fig, ax = plt.subplots(figsize=(5, 4))
    t = steps["west_temp_c"]
    ax.hist(t, bins=np.arange(np.floor(t.min() * 10) / 10, t.max() + 0.1, 0.1), color="tab:blue")
    ax.axvspan(*COMFORT_BAND_C, color="green", alpha=0.08)
    ax.set_xlabel("West zone temperature (°C)")
    ax.set_ylabel("timesteps")
    ax.set_title(f"{title[0]}, {title[1]}")
    return _save(fig, path)


def convergence(run_dir: Path, path: Path | None = None) -> Path:
    """Figure 3: mean reward per step of each finished episode against timesteps, per weather."""
    episodes = pd.read_csv(run_dir / "episodes.csv")
    fig, ax = plt.subplots(figsize=(7, 4))
    for weather, g in episodes.groupby("weather"):
        ax.plot(g["timesteps"], g["reward_mean"], "o-", ms=3, label=weather)
    ax.set_xlabel("timesteps")
    ax.set_ylabel("mean reward per step (episode)")
    ax.set_title(f"Training convergence: {run_dir.name}")
    ax.legend()
    return _save(fig, path or run_dir / "convergence.png")


def episode(episode_dir: Path, path: Path | None = None) -> Path:
    """One episode as time series: temperatures with the band, setpoints, fan flows, power."""
    steps = read_steps(episode_dir)
    summary = summarize(steps)
    setpoints = [c for c in steps.columns if c.endswith("_setpoint_c")]
    fans = [c for c in steps.columns if c.endswith("_fan_kg_s")]
    panels = 2 + bool(setpoints) + bool(fans)
    fig, axes = plt.subplots(panels, 1, figsize=(11, 2.6 * panels), sharex=True)
    ax = axes[0]
    for col in ("outdoor_temp_c", "west_temp_c", "east_temp_c"):
        ax.plot(steps["time"], steps[col], lw=0.7, label=col.removesuffix("_temp_c"))
    ax.axhspan(*COMFORT_BAND_C, color="green", alpha=0.1)
    ax.set_ylabel("°C")
    ax.legend(loc="upper right", fontsize=8)
    i = 1
    for cols, unit in ((setpoints, "setpoint °C"), (fans, "fan kg/s")):
        if cols:
            for col in cols:
                axes[i].plot(steps["time"], steps[col], lw=0.7, label=col)
            axes[i].set_ylabel(unit)
            axes[i].legend(loc="upper right", fontsize=8)
            i += 1
    ax = axes[i]
    for col in ("power_w", "it_power_w", "hvac_power_w"):
        ax.plot(steps["time"], steps[col] / 1000, lw=0.7, label=col.removesuffix("_w"))
    ax.set_ylabel("kW")
    ax.legend(loc="upper right", fontsize=8)
    text = (
        f"power {summary['power_kw']:.1f} kW (IT {summary['it_power_kw']:.1f}, HVAC {summary['hvac_power_kw']:.1f});  "
        f"West {summary['west_temp_mean']:.2f} ± {summary['west_temp_std']:.2f} °C;  "
        f"East {summary['east_temp_mean']:.2f} ± {summary['east_temp_std']:.2f} °C;  "
        f"in 22–25 °C {summary['in_band_pct']:.2f} %;  reward {summary['reward_mean']:.3f}/step"
    )
    fig.suptitle(f"{episode_dir.name}\n{text}", fontsize=9)
    return _save(fig, path or episode_dir / "episode.png")


def plot_path(path: Path) -> Path:
    """A run directory draws its convergence; an episode directory its time series."""
    if (path / "episodes.csv").is_file():
        return convergence(path)
    if (path / STEPS_FILE).is_file():
        return episode(path)
    if (path / SUMMARY_FILE).is_file():
        raise FileNotFoundError(f"{path} kept only its summary (older episodes are pruned); pick a newer one")
    raise FileNotFoundError(f"{path} is neither a run directory (episodes.csv) nor an episode directory ({STEPS_FILE})")
