"""Results over several training runs of one recipe (seeds): a figure over one run is an anecdote.

Policies evaluated under one label are one controller's runs. Per weather and over all weathers, each figure is
reported as the mean over runs with a 95 % percentile bootstrap interval, and over all weathers also as the
interquartile mean (IQM), the estimator Agarwal et al. (2021, "Deep Reinforcement Learning at the Edge of the
Statistical Precipice") recommend for few runs; the overall interval is their stratified bootstrap: runs are
resampled within each weather. rliable implements exactly this, but its release (1.2.0) needs `arch<8`, and
arch 7 does not import under pandas 3, so the same estimator is computed with `scipy.stats.bootstrap` here.
"""

from __future__ import annotations

import numpy as np
import pandas as pd
from scipy import stats

# What the seed tables summarise, with how each reads (higher or lower is better is the reader's call).
METRICS = {
    "energy_change_pct": "energy vs built-in (%)",
    "hvac_energy_change_pct": "HVAC energy vs built-in (%)",  # BOPTEST's figures (buildings/scoring/kpis.py)
    "cost_change_pct": "cost vs built-in (%)",
    "emissions_change_pct": "emissions vs built-in (%)",
    "in_band_pct": "in band (%)",
    "discomfort_kh": "discomfort (K·h/zone)",
    "occupied_discomfort_kh": "occupied discomfort (K·h/zone)",  # thermostat bounds (buildings/scoring/comfort.py)
    "power_kw": "power (kW)",
    "energy_kwh": "energy (kWh)",
}
CONFIDENCE = 0.95
RESAMPLES = 5000
OVERALL = "all"


def iqm(x: np.ndarray, axis: int = -1) -> np.ndarray | float:
    """The interquartile mean: the mean of the middle half."""
    return stats.trim_mean(np.asarray(x, float), 0.25, axis=axis)


def interval(groups: list[np.ndarray], statistic=np.mean, seed: int = 0) -> tuple[float, float, float]:
    """(point, low, high): `statistic` (a numpy reduction taking `axis`) over all values, with a stratified
    percentile bootstrap interval (each group, a weather's runs, resampled on its own); none from a single run."""
    groups = [np.asarray(g, float) for g in groups if len(g)]
    point = float(statistic(np.concatenate(groups), axis=-1))
    if max(len(g) for g in groups) < 2:
        return point, float("nan"), float("nan")
    result = stats.bootstrap(
        tuple(groups), lambda *xs, axis=-1: statistic(np.concatenate(xs, axis=axis), axis=axis),
        n_resamples=RESAMPLES, method="percentile", confidence_level=CONFIDENCE, vectorized=True,
        random_state=np.random.default_rng(seed),
    )  # fmt: skip
    return point, float(result.confidence_interval.low), float(result.confidence_interval.high)


def with_changes(df: pd.DataFrame, baseline: str) -> pd.DataFrame:
    """Each row's energy against the baseline's on the same weather (`energy_change_pct`), where both exist.

    On noisy years (a `weather_seed` per row, sweep.py) each year is compared with the baseline's same year: the
    years differ more than the controllers do, so pairing them keeps the year's weather out of the change."""
    df = df.copy()
    keys = ["weather"]
    if "weather_seed" in df.columns and df["weather_seed"].notna().all():
        keys.append("weather_seed")
    for key in ("energy_kwh" if "energy_kwh" in df.columns else "power_kw", "hvac_energy_kwh", "cost", "emissions_kg"):
        if key not in df.columns:  # BOPTEST's figures (buildings/scoring/kpis.py), where the rows have them
            continue
        name = "energy" if key in ("energy_kwh", "power_kw") else key.removesuffix("_kwh").removesuffix("_kg")
        df[f"{name}_change_pct"] = 100 * (df[key] / _paired(df, baseline, key, keys) - 1)
    return df


def _paired(df: pd.DataFrame, baseline: str, key: str, keys: list[str]) -> pd.Series:
    """The baseline's mean `key` for each row's weather (and year, where `keys` has it); by weather alone for a
    row whose year the baseline did not run."""
    base = df[df.controller == baseline]
    by_weather = df["weather"].map(base.groupby("weather")[key].mean())
    if len(keys) == 1:
        return by_weather
    by_year = base.groupby(keys)[key].mean()
    paired = pd.Series(pd.MultiIndex.from_frame(df[keys]).map(by_year), index=df.index, dtype=float)
    return paired.fillna(by_weather)


def seed_table(df: pd.DataFrame, baseline: str) -> pd.DataFrame:
    """Per controller with more than one run: each metric per weather and over all weathers (mean, interval,
    IQM), from results rows with a `run` column."""
    df = with_changes(df, baseline)
    rows = []
    for controller, runs in df.groupby("controller", sort=False):
        n = runs["run"].nunique() if "run" in runs else 1
        if n < 2:
            continue
        for metric in (m for m in METRICS if m in runs and runs[m].notna().any()):
            per_weather = {w: g[metric].dropna().to_numpy() for w, g in runs.groupby("weather", sort=False)}
            for weather, values in per_weather.items():
                point, low, high = interval([values])
                rows.append(dict(controller=controller, weather=weather, metric=metric, runs=len(values),
                                 mean=point, low=low, high=high, iqm=float("nan")))  # fmt: skip
            point, low, high = interval(list(per_weather.values()))
            q, q_low, q_high = interval(list(per_weather.values()), iqm)
            rows.append(dict(controller=controller, weather=OVERALL, metric=metric, runs=n, mean=point, low=low,
                             high=high, iqm=q, iqm_low=q_low, iqm_high=q_high))  # fmt: skip
    return pd.DataFrame(rows)


def collapse(df: pd.DataFrame) -> pd.DataFrame:
    """One row per (controller, weather): numeric figures averaged over runs, for the per-controller tables and
    figures; `runs` counts them."""
    if "run" not in df.columns or not df.duplicated(["controller", "weather"]).any():
        return df
    numeric = [c for c in df.columns if pd.api.types.is_numeric_dtype(df[c]) and c not in ("controller", "weather")]
    first = [c for c in df.columns if c not in numeric and c not in ("controller", "weather")]
    grouped = df.groupby(["controller", "weather"], sort=False)
    out = grouped[numeric].mean().join(grouped[first].first()).join(grouped.size().rename("runs")).reset_index()
    return out[[c for c in df.columns if c in out.columns] + ["runs"]]


def _cell(r: pd.Series) -> str:
    if np.isnan(r["low"]):
        return f"{r['mean']:.2f}"
    return f"{r['mean']:.2f} [{r['low']:.2f}, {r['high']:.2f}]"


def seeds_markdown(table: pd.DataFrame) -> str:
    """The seed table as markdown: per controller, metric rows by weather columns, then the IQM."""
    if table.empty:
        return ""
    lines = ["", "## Across runs (seeds)", "",
             f"Mean over runs with a {CONFIDENCE:.0%} percentile bootstrap interval; over all weathers the interval "
             "is the stratified bootstrap (runs resampled within each weather), and the interquartile mean (IQM) "
             "is given beside it."]  # fmt: skip
    for controller, t in table.groupby("controller", sort=False):
        weathers = list(dict.fromkeys(t["weather"]))
        n = int(t[t.weather == OVERALL]["runs"].max())
        lines += ["", f"**{controller}** ({n} runs)", "", "| figure | " + " | ".join(weathers) + " | IQM, all |",
                  "|---" * (len(weathers) + 2) + "|"]  # fmt: skip
        for metric, m in t.groupby("metric", sort=False):
            by = m.set_index("weather")
            cells = [_cell(by.loc[w]) if w in by.index else "–" for w in weathers]
            overall = by.loc[OVERALL]
            q = f"{overall['iqm']:.2f} [{overall['iqm_low']:.2f}, {overall['iqm_high']:.2f}]"
            lines.append(f"| {METRICS[metric]} | " + " | ".join(cells) + f" | {q} |")
    return "\n".join(lines) + "\n"
