"""Results for any building spec: average power (the reward's power signal) and % in band per temperature,
per weather, against the baseline (its model's own controls). The data center keeps the paper's layout."""

from __future__ import annotations

from pathlib import Path

import pandas as pd


def is_generic(df: pd.DataFrame) -> bool:
    """A sweep over a building other than the paper's two zones (no West/East columns)."""
    return "west_temp_mean" not in df.columns


def band_of(df: pd.DataFrame) -> tuple[float, float] | None:
    """The reward band the episodes were counted against (their summaries record it)."""
    if "band_low_c" not in df.columns:
        return None
    return float(df["band_low_c"].iloc[0]), float(df["band_high_c"].iloc[0])


def comparable(df: pd.DataFrame) -> tuple[pd.DataFrame, str]:
    """The rows to average across controllers: the weathers every controller finished (an episode that failed,
    as the CRAC's own controls do on CO, must not tilt one controller's average), and a note saying so."""
    per = [set(g) for _, g in df.groupby("controller", sort=False)["weather"]]
    common = set.intersection(*per) if per else set()
    if all(s == common for s in per):
        return df, ""
    kept = df[df["weather"].isin(common)]
    left = [w for w in dict.fromkeys(df["weather"]) if w not in common]
    return kept, (
        f"Averages over {', '.join(dict.fromkeys(kept['weather'])) or 'no weather'}, the weathers every controller "
        f"finished (not {', '.join(left)}).\n"
    )


def table_markdown(df: pd.DataFrame, baseline: str) -> str:
    zones = [c.removesuffix("_in_band_pct") for c in df.columns if c.endswith("_in_band_pct") and c != "in_band_pct"]
    band = band_of(df)
    named = "in band" if band is None else "in {:g}–{:g} °C".format(*band)
    base = df[df.controller == baseline].set_index("weather")["power_kw"]
    head = "| Controller | Weather | power (kW) | vs baseline | " + " | ".join(f"{z} {named}" for z in zones)
    lines = [head + f" | all {named} |", "|---" * (5 + len(zones)) + "|"]
    for _, r in df.iterrows():
        change = (
            "–"
            if r.controller == baseline or r.weather not in base
            else f"{100 * (r.power_kw / base[r.weather] - 1):+.1f} %"
        )
        cells = [f"{r[f'{z}_in_band_pct']:.2f} %" for z in zones]
        lines.append(
            f"| {r.controller} | {r.weather} | {r.power_kw:.2f} | {change} | " + " | ".join(cells)
            + f" | {r.in_band_pct:.2f} % |"
        )  # fmt: skip
    shared, note = comparable(df)
    avg = shared.groupby("controller", sort=False)[["power_kw", "in_band_pct"]].mean()
    lines += ["", *([note] if note else []), f"| Controller | mean power (kW) | vs baseline | all {named} |",
              "|---|---|---|---|"]  # fmt: skip
    for c, r in avg.iterrows():
        change = (
            "–"
            if c == baseline or baseline not in avg.index
            else f"{100 * (r.power_kw / avg.power_kw[baseline] - 1):+.1f} %"
        )
        lines.append(f"| {c} | {r.power_kw:.2f} | {change} | {r.in_band_pct:.2f} % |")
    return "\n".join(lines) + "\n"


def write_results(df: pd.DataFrame, out_dir: Path, baseline: str) -> list[Path]:
    out_dir.mkdir(parents=True, exist_ok=True)
    df.to_csv(out_dir / "results.csv", index=False)
    (out_dir / "results.md").write_text("# Evaluation\n\n" + table_markdown(df, baseline))
    return [out_dir / "results.csv", out_dir / "results.md", *figures(df, out_dir)]


def figures(df: pd.DataFrame, out_dir: Path) -> list[Path]:
    """The building's own figures: its zones against its band, its power; no data-center references."""
    from parallel_eplus.evaluation import plots

    files = []
    if plots.zones_of(df):
        files.append(
            plots.temperature_comparison(df, out_dir / "temperatures.png", band_of(df) or plots.COMFORT_BAND_C)
        )
    files.append(plots.power_comparison(df, out_dir / "power.png"))
    return files
