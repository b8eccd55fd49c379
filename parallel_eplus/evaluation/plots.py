"""Figures: the paper's Figures 3 and 4, power per controller, and one episode as time series."""

from __future__ import annotations

import json
import textwrap
import zlib
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402

from parallel_eplus import io  # noqa: E402
from parallel_eplus.buildings.building import load_building  # noqa: E402
from parallel_eplus.buildings.datacenter import COMFORT_BAND_C  # noqa: E402
from parallel_eplus.buildings.scoring.reward import RewardConfig  # noqa: E402
from parallel_eplus.buildings.weather.files import WEATHER_FILES  # noqa: E402
from parallel_eplus.engine.episode import (  # noqa: E402
    REWARD_PARTS,
    STEP_FLAGS,
    SUMMARY_FILE,
    read_steps,
    summarize,
)

# One colour per controller in every figure: the references fixed, other labels by a stable hash.
REFERENCE_COLORS = {"Baseline": "tab:gray", "Rule-based": "tab:green"}
_POLICY_COLORS = ["tab:blue", "tab:orange", "tab:red", "tab:purple", "tab:brown", "tab:pink", "tab:olive", "tab:cyan"]
ZONE_COLORS = {"west": "tab:blue", "east": "tab:orange"}
_ZONE_PALETTE = ["tab:blue", "tab:orange", "tab:green", "tab:red", "tab:purple", "tab:brown", "tab:pink", "tab:cyan"]


def zones_of(df: pd.DataFrame) -> list[str]:
    """The temperatures a results table reports (the data center's "west", "east"; any spec's own names)."""
    return [c.removesuffix("_temp_mean") for c in df.columns if c.endswith("_temp_mean")]


def zone_colors(zones: list[str]) -> dict[str, str]:
    return {z: ZONE_COLORS.get(z, _ZONE_PALETTE[i % len(_ZONE_PALETTE)]) for i, z in enumerate(zones)}


def zone_label(zone: str) -> str:
    return f"{zone.title()} zone" if zone in ZONE_COLORS else zone


def band_label(band: tuple[float, float]) -> str:
    return "{:g}–{:g} °C".format(*band)


def controller_color(label: str) -> str:
    """The colour a controller has in every figure (same label, same colour, across runs)."""
    if label in REFERENCE_COLORS:
        return REFERENCE_COLORS[label]
    return _POLICY_COLORS[zlib.crc32(label.encode()) % len(_POLICY_COLORS)]


def controller_colors(labels) -> dict[str, str]:
    """The colours of one figure's controllers: each its own `controller_color`, unless an earlier label in
    the same figure already took it (two policies hashed alike must not look alike); then the next free one."""
    colors: dict[str, str] = {}
    for label in dict.fromkeys(labels):
        own = controller_color(label)
        if label not in REFERENCE_COLORS and own in colors.values():
            start = _POLICY_COLORS.index(own)
            rotated = _POLICY_COLORS[start:] + _POLICY_COLORS[:start]
            own = next((c for c in rotated if c not in colors.values()), own)  # more policies than colours: reuse
        colors[label] = own
    return colors


def with_references(df: pd.DataFrame, references: pd.DataFrame | None) -> pd.DataFrame:
    """Puts the built-in and rule-based controllers' rows (same weathers) before a sweep that lacks them."""
    if references is None:
        return df
    refs = references[references["controller"].isin(REFERENCE_COLORS) & references["weather"].isin(df["weather"])]
    refs = refs[~refs["controller"].isin(df["controller"])]
    return pd.concat([refs, df], ignore_index=True) if not refs.empty else df


def find_references(out_dir: Path) -> pd.DataFrame | None:
    """The saved reference sweep (`results/reference/results.csv`) nearest above `out_dir`, if any."""
    for parent in [out_dir, *out_dir.resolve().parents]:
        candidate = parent / "reference" / "results.csv"
        if candidate.is_file() and candidate.parent != out_dir.resolve():
            return pd.read_csv(candidate)
    return None


def _figure(figsize):
    return plt.subplots(figsize=figsize, layout="constrained")


def _save(fig, path: Path) -> Path:
    with io.atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=120, format=Path(path).suffix[1:])
    plt.close(fig)
    return path


def temperature_comparison(df: pd.DataFrame, path: Path, band: tuple[float, float] = COMFORT_BAND_C) -> Path:
    """Figure 4 left: per controller, weather and zone a min-max line with a mean +- std box.

    Any building's: its reported temperatures (`zones_of`) and its reward band."""
    controllers = list(dict.fromkeys(df["controller"]))
    weathers = weather_order(df["weather"])
    colors = zone_colors(zones_of(df))
    width = 0.7 / len(colors)
    fig, ax = _figure((min(16, max(7, 0.45 * len(controllers) * len(weathers) + 2.5)), 4.4))
    x, ticks, labels = 0.0, [], []
    for c in controllers:
        for w in weathers:
            r = df[(df.controller == c) & (df.weather == w)]
            if r.empty:
                continue
            r = r.iloc[0]
            for k, (zone, color) in enumerate(colors.items()):
                xi = x + (k - (len(colors) - 1) / 2) * width
                ax.vlines(xi, r[f"{zone}_temp_min"], r[f"{zone}_temp_max"], color=color, lw=1)
                mean, std = r[f"{zone}_temp_mean"], r[f"{zone}_temp_std"]
                ax.add_patch(
                    plt.Rectangle((xi - 0.34 * width, mean - std), 0.68 * width, 2 * std, color=color, alpha=0.8)
                )
            ticks.append(x)
            labels.append(f"{w}")
            x += 1
        x += 0.6
    ax.axhspan(*band, color="green", alpha=0.08)
    ax.set_xticks(ticks, labels)
    ax.set_ylabel("zone temperature (°C)")
    ax.set_title("Zone temperatures (line: min–max, box: mean ± std)", fontsize=10)
    handles = [plt.Rectangle((0, 0), 1, 1, color=c, alpha=0.8) for c in colors.values()]
    handles.append(plt.Rectangle((0, 0), 1, 1, color="green", alpha=0.15))
    names = [zone_label(z) for z in colors] + [band_label(band)]
    fig.legend(handles, names, loc="outside right upper", fontsize=8)
    # Controller names under their group of weathers.
    group = len(weathers)
    colors = controller_colors(controllers)
    for i, c in enumerate(controllers):
        name = textwrap.fill(c, max(12, 5 * group))
        ax.annotate(name, xy=(i * (group + 0.6) + (group - 1) / 2, 0), xycoords=("data", "axes fraction"),
                    xytext=(0, -24), textcoords="offset points", ha="center", va="top", fontsize=8,
                    color=colors[c])  # fmt: skip
    return _save(fig, path)


def weather_order(weathers) -> list[str]:
    """The paper's weathers in its order (CA, CO, FL, IL, VA), others after them as they came: a weather the
    first controller did not finish (a failed episode) keeps its place."""
    known, seen = list(WEATHER_FILES), list(dict.fromkeys(weathers))
    return sorted(seen, key=lambda w: known.index(w) if w in known else len(known) + seen.index(w))


def power_comparison(df: pd.DataFrame, path: Path, runs: pd.DataFrame | None = None) -> Path:
    """Average total power per controller and weather; with every run's rows (`runs`), a controller with several
    runs is drawn at their mean with its 95 % bootstrap interval (seeds.py)."""
    from parallel_eplus.evaluation.seeds import interval

    table = df.pivot(index="weather", columns="controller", values="power_kw")
    table = table.loc[weather_order(df["weather"]), list(dict.fromkeys(df["controller"]))]
    errors = np.zeros((len(table.columns), 2, len(table.index)))
    if runs is not None and "run" in runs.columns:
        for i, c in enumerate(table.columns):
            for j, w in enumerate(table.index):
                values = runs[(runs.controller == c) & (runs.weather == w)]["power_kw"].to_numpy()
                if len(values) > 1:
                    mean, low, high = interval([values])
                    errors[i, :, j] = mean - low, high - mean
    fig, ax = _figure((9, 4))
    colors = controller_colors(table.columns)
    table.plot.bar(ax=ax, rot=0, color=[colors[c] for c in table.columns], legend=False,
                   yerr=errors if errors.any() else None, capsize=3, error_kw={"lw": 1})  # fmt: skip
    ax.set_ylabel("average total power (kW)")
    ax.set_xlabel("test weather")
    ax.set_title("Average power per controller and weather", fontsize=10)
    fig.legend(loc="outside right upper", fontsize=8, title="controller", title_fontsize=8)
    return _save(fig, path)


def west_zone_histogram(episode_dir: Path, title: tuple[str, str], path: Path) -> Path:
    """Figure 4 right: distribution of West-zone temperatures for one controller and weather."""
    steps = read_steps(episode_dir)
    fig, ax = _figure((5, 4))
    t = steps["west_temp_c"]
    ax.hist(t, bins=np.arange(np.floor(t.min() * 10) / 10, t.max() + 0.1, 0.1), color=controller_color(title[0]))
    ax.axvspan(*COMFORT_BAND_C, color="green", alpha=0.08)
    ax.set_xlabel("West zone temperature (°C)")
    ax.set_ylabel("timesteps")
    ax.set_title(f"{title[0]}, {title[1]}", fontsize=10, wrap=True)
    return _save(fig, path)


def reference_rewards(run_dir: Path, weathers: list[str]) -> dict[str, float]:
    """The built-in and rule-based controllers' mean reward per step over `weathers`, from the reference sweep
    above `run_dir`; none when the run trained on other reward constants than that sweep's (the defaults)."""
    refs, config = find_references(run_dir), run_dir / "config.json"
    if refs is None or "reward_mean" not in refs or not config.is_file():
        return {}
    if RewardConfig.from_any(json.loads(config.read_text()).get("reward")) != RewardConfig():
        return {}  # another reward: the references' rewards are not on this scale
    rows = refs[refs["controller"].isin(REFERENCE_COLORS) & refs["weather"].isin(weathers)]
    return {
        label: g["reward_mean"].mean()
        for label, g in rows.groupby("controller", sort=False)
        if set(g["weather"]) == set(weathers)
    }


def convergence(run_dir: Path, path: Path | None = None) -> Path:
    """Figure 3: mean reward per step of each finished episode against timesteps, per weather, beside the
    built-in and rule-based controllers' reward on the same weathers (`reference_rewards`)."""
    episodes = pd.read_csv(run_dir / "episodes.csv")
    weathers = list(dict.fromkeys(episodes["weather"]))
    fig, ax = _figure((8, 4))
    for i, (weather, g) in enumerate(episodes.groupby("weather", sort=False)):
        color = _POLICY_COLORS[i % len(_POLICY_COLORS)]  # never a reference's grey or green
        ax.plot(g["timesteps"], g["reward_mean"], "o-", ms=3, label=weather, color=color)
    for label, value in reference_rewards(run_dir, weathers).items():
        ax.axhline(value, color=REFERENCE_COLORS[label], linestyle=":" if label == "Baseline" else "--", lw=1,
                   label=f"{label}, mean of {'/'.join(weathers)}")  # fmt: skip
    ax.set_xlabel("timesteps")
    ax.set_ylabel("mean reward per step (episode)")
    ax.set_title(f"Training convergence: {run_dir.name}", fontsize=10)
    fig.legend(loc="outside right upper", fontsize=8, title="training weather", title_fontsize=8)
    return _save(fig, path or run_dir / "convergence.png")


def episode(episode_dir: Path, path: Path | None = None) -> Path:
    """One episode as time series: temperatures with the band, the actions (°C and other units), power.

    Any building's: its summary names the building (None: the data center), whose sensors, actions,
    reward temperatures and band the panels show."""
    steps = read_steps(episode_dir)
    saved = json.loads((episode_dir / SUMMARY_FILE).read_text()) if (episode_dir / SUMMARY_FILE).is_file() else {}
    building = load_building(saved.get("building"))
    summary = summarize(steps, building.comfort)
    sensors = set(building.sensor_names)
    skip = {"reward", *REWARD_PARTS, *STEP_FLAGS}
    actions = [c for c in steps.columns[1:] if c not in sensors and c not in skip]
    in_c = [c for c in actions if c.endswith("_c")]
    other = [c for c in actions if not c.endswith("_c")]
    temps = [c for c in ("outdoor_temp_c",) if c in steps.columns] + list(building.temperatures)
    power = [c for c in building.sensor_names if c.endswith("_w")]
    panels = 2 + bool(in_c) + bool(other)
    fig, axes = plt.subplots(panels, 1, figsize=(12, 2.6 * panels), sharex=True, layout="constrained")
    ax = axes[0]
    for col in temps:
        ax.plot(steps["time"], steps[col], lw=0.7, label=col.removesuffix("_c").removesuffix("_temp"))
    if building.comfort.per_step:  # each zone's own thermostat bounds (docs/kpis.md): the distinct ones, dashed
        for lo, hi in dict.fromkeys(building.comfort.bound_names):
            ax.fill_between(steps["time"], steps[lo], steps[hi], step="pre", color="green", alpha=0.08, lw=0)
    else:
        ax.axhspan(*building.band, color="green", alpha=0.1)
    ax.set_ylabel("°C")
    ax.legend(loc="upper left", bbox_to_anchor=(1.0, 1.0), fontsize=8)
    i = 1
    for cols, unit in ((in_c, "action °C"), (other, "action")):
        if cols:
            for col in cols:
                axes[i].plot(steps["time"], steps[col], lw=0.7, label=col)
            axes[i].set_ylabel(unit)
            axes[i].legend(loc="upper left", bbox_to_anchor=(1.0, 1.0), fontsize=8)
            i += 1
    ax = axes[i]
    for col in power:
        ax.plot(steps["time"], steps[col] / 1000, lw=0.7, label=col.removesuffix("_w"))
    ax.set_ylabel("kW")
    ax.legend(loc="upper left", bbox_to_anchor=(1.0, 1.0), fontsize=8)
    parts = [f"power {summary['power_kw']:.1f} kW"]
    if "it_power_kw" in summary and "hvac_power_kw" in summary:
        parts[0] += f" (IT {summary['it_power_kw']:.1f}, HVAC {summary['hvac_power_kw']:.1f})"
    for zone in zones_of(pd.DataFrame([summary])):
        parts.append(f"{zone_label(zone)} {summary[f'{zone}_temp_mean']:.2f} ± {summary[f'{zone}_temp_std']:.2f} °C")
    named = "own thermostat bounds" if building.comfort.per_step else band_label(building.band)
    parts.append(f"in {named} {summary['in_band_pct']:.2f} %")
    parts.append(f"reward {summary['reward_mean']:.3f}/step")
    text = ";  ".join(parts)
    fig.suptitle(f"{episode_dir.name}\n{textwrap.fill(text, 160)}", fontsize=9)
    return _save(fig, path or episode_dir / "episode.png")
