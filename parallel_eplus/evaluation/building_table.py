"""Results for any building spec: average power (the reward's power signal) and % in band per temperature,
per weather, against the baseline (its model's own controls). The data center keeps the paper's layout."""

from __future__ import annotations

from pathlib import Path

import pandas as pd


def is_generic(df: pd.DataFrame) -> bool:
    """A sweep over a building other than the paper's two zones (no West/East columns)."""
    return "west_temp_mean" not in df.columns


def table_markdown(df: pd.DataFrame, baseline: str) -> str:
    zones = [c.removesuffix("_in_band_pct") for c in df.columns if c.endswith("_in_band_pct") and c != "in_band_pct"]
    base = df[df.controller == baseline].set_index("weather")["power_kw"]
    head = "| Controller | Weather | power (kW) | vs baseline | " + " | ".join(f"{z} in band" for z in zones)
    lines = [head + " | all in band |", "|---" * (5 + len(zones)) + "|"]
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
    return "\n".join(lines) + "\n"


def write_results(df: pd.DataFrame, out_dir: Path, baseline: str) -> list[Path]:
    out_dir.mkdir(parents=True, exist_ok=True)
    df.to_csv(out_dir / "results.csv", index=False)
    (out_dir / "results.md").write_text("# Evaluation\n\n" + table_markdown(df, baseline))
    return [out_dir / "results.csv", out_dir / "results.md"]
