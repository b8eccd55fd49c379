"""The sweep's results on disk: results.csv, the paper's Table 1 layout in results.md, and the figures.

Another building's results (its own zones and power) go through `building_table.py` instead.
"""

from __future__ import annotations

import logging
from pathlib import Path

import pandas as pd

from parallel_eplus import io
from parallel_eplus.buildings.datacenter import COMFORT_BAND_C
from parallel_eplus.engine.episode import STEPS_FILE
from parallel_eplus.evaluation.building_table import comparable
from parallel_eplus.evaluation.controllers import BASELINE_LABEL

log = logging.getLogger(__name__)


RESULT_COLUMNS = [
    "controller", "weather", "reward_mean", "power_kw", "it_power_kw", "hvac_power_kw",
    "west_temp_mean", "west_temp_std", "west_temp_min", "west_temp_max",
    "east_temp_mean", "east_temp_std", "east_temp_min", "east_temp_max",
    "west_in_band_pct", "east_in_band_pct", "in_band_pct",
    "energy_kwh", "peak_power_kw", "discomfort_kh", "west_discomfort_kh", "east_discomfort_kh", "steps", "episode_dir",
]  # fmt: skip


def table_markdown(df: pd.DataFrame) -> str:
    """The paper's Table 1 layout: weathers down, controllers across (reward, power), then averages."""
    controllers = list(dict.fromkeys(df["controller"]))
    weathers = list(dict.fromkeys(df["weather"]))
    by = df.set_index(["controller", "weather"])
    head = "| Test weather | " + " | ".join(f"{c}: reward | {c}: power (kW)" for c in controllers) + " |"
    lines = [head, "|" + "---|" * (1 + 2 * len(controllers))]
    for w in weathers:
        cells = []
        for c in controllers:
            r = by.loc[(c, w)] if (c, w) in by.index else None
            cells += ["–", "–"] if r is None else [f"{r.reward_mean:.2f}", f"{r.power_kw:.1f}"]
        lines.append(f"| {w} | " + " | ".join(cells) + " |")
    shared, note = comparable(df)  # averages over the weathers every controller finished
    avg = shared.groupby("controller", sort=False)["power_kw"].mean()
    base = avg.get(BASELINE_LABEL)
    cells = []
    for c in controllers:
        change = "" if base is None or c == BASELINE_LABEL else f" ({100 * (avg[c] / base - 1):+.1f} %)"
        reward_avg = shared[shared.controller == c]["reward_mean"].mean()
        cells += [f"{reward_avg:.2f}", f"**{avg[c]:.1f}**{change}"]
    lines.append("| **Average** | " + " | ".join(cells) + " |")

    band = "{:g}–{:g} °C".format(*COMFORT_BAND_C)  # the data center's (its spec's reward band)
    lines += ["", f"Zone temperatures (°C) and share of zone samples within {band}:", ""]
    lines.append(f"| Controller | Weather | West mean ± std [min, max] | East mean ± std [min, max] | in {band} |")
    lines.append("|---|---|---|---|---|")
    for _, r in df.iterrows():
        lines.append(
            f"| {r.controller} | {r.weather} "
            f"| {r.west_temp_mean:.2f} ± {r.west_temp_std:.2f} [{r.west_temp_min:.1f}, {r.west_temp_max:.1f}] "
            f"| {r.east_temp_mean:.2f} ± {r.east_temp_std:.2f} [{r.east_temp_min:.1f}, {r.east_temp_max:.1f}] "
            f"| {r.in_band_pct:.2f} % |"
        )
    share = shared.groupby("controller", sort=False)["in_band_pct"].mean()
    lines += [
        "",
        *([note] if note else []),
        f"| Controller | mean power (kW) | change vs baseline | zone samples in {band} |",
        "|---|---|---|---|",
    ]
    for c in controllers:
        change = "–" if base is None or c == BASELINE_LABEL else f"{100 * (avg[c] / base - 1):+.1f} %"
        lines.append(f"| {c} | {avg[c]:.1f} | {change} | {share[c]:.2f} % |")
    if "energy_kwh" in shared.columns:  # BOPTEST's figures (buildings/scoring/comfort.py), per weather's year, averaged
        kpi = shared.groupby("controller", sort=False)[["energy_kwh", "peak_power_kw", "discomfort_kh"]].mean()
        lines += [
            "",
            "BOPTEST's figures, averaged over the weathers: energy over the run, peak electric power (highest "
            "15-minute mean), thermal discomfort outside the band:",
            "",
            "| Controller | energy (MWh) | peak (kW) | discomfort (K·h per zone) |",
            "|---|---|---|---|",
        ]
        for c in controllers:
            r = kpi.loc[c]
            lines.append(f"| {c} | {r.energy_kwh / 1000:,.1f} | {r.peak_power_kw:.1f} | {r.discomfort_kh:.2f} |")
    return "\n".join(lines) + "\n"


def failures_markdown(failures: list[dict]) -> str:
    """The episodes a sweep left out, for the end of results.md: a table that silently lost rows would mislead."""
    if not failures:
        return ""
    lines = ["", "## Episodes that did not finish", "", "| Controller | Weather | EnergyPlus said | episode |",
             "|---|---|---|---|"]  # fmt: skip
    lines += [f"| {f['controller']} | {f['weather']} | {f['error']} | `{f['episode_dir']}` |" for f in failures]
    return "\n".join(lines) + "\n"


# BOPTEST's figures in a summary (buildings/scoring/kpis.py), kept in results.csv beside the paper's columns
KPI_PREFIXES = ("hvac_", "cost", "emissions_kg", "energy_kwh_m2", "floor_area_m2")


def write_results(df: pd.DataFrame, out_dir: Path, histogram: tuple[str, str] | None = None) -> list[Path]:
    """results.csv (every run's rows), results.md and the figures; returns the files written.

    Several runs of one controller (policies sharing a label) are averaged in the tables and figures, and
    reported across runs, with intervals, in results.md's last section and seeds.csv (seeds.py)."""
    from parallel_eplus.evaluation import building_table, plots, seeds

    across = seeds.seed_table(df, BASELINE_LABEL)
    full, df = df, seeds.collapse(df)
    if building_table.is_generic(df):  # another building: its power and zones, no paper figures
        return building_table.write_results(df, out_dir, BASELINE_LABEL, full, across)
    out_dir.mkdir(parents=True, exist_ok=True)
    columns = [c for c in ("controller", "run", *RESULT_COLUMNS[1:]) if c in full.columns]
    boptest = ""
    if "hvac_energy_kwh" in df.columns:  # the spec's [kpis]: BOPTEST's figures, each also over the built-in's
        full = building_table.with_ratios(full, BASELINE_LABEL)
        kpis = [c for c in full.columns if c not in columns and c.startswith(KPI_PREFIXES)]
        columns += sorted(kpis, key=lambda c: c.endswith("_vs_builtin"))  # the figures, then their ratios
        boptest = "\n" + building_table.boptest_markdown(df, BASELINE_LABEL)
    io.write_text(out_dir / "results.csv", full[columns].to_csv(index=False))
    io.write_text(
        out_dir / "results.md", "# Evaluation\n\n" + table_markdown(df) + boptest + seeds.seeds_markdown(across)
    )
    files = [out_dir / "results.csv", out_dir / "results.md"]
    if not across.empty:
        io.write_text(out_dir / "seeds.csv", across.to_csv(index=False))
        files.append(out_dir / "seeds.csv")
    shown = plots.with_references(df, plots.find_references(out_dir))  # a lone policy beside the references
    files.append(plots.temperature_comparison(shown, out_dir / "temperatures.png"))
    files.append(plots.power_comparison(shown, out_dir / "power.png", full))
    if histogram is None:
        controller = df["controller"].iloc[-1]
        weathers = list(df[df.controller == controller]["weather"])
        histogram = (controller, "VA" if "VA" in weathers else weathers[-1])
    row = df[(df.controller == histogram[0]) & (df.weather == histogram[1])]
    if row.empty:
        log.warning(
            "no West-zone histogram: no episode of %r on %s (controllers: %s)",
            histogram[0], histogram[1], ", ".join(df["controller"].unique()),
        )  # fmt: skip
    elif not (Path(row.iloc[0]["episode_dir"]) / STEPS_FILE).is_file():  # a row kept from another machine's run
        log.warning("no West-zone histogram: %s holds no steps", row.iloc[0]["episode_dir"])
    else:
        files.append(
            plots.west_zone_histogram(Path(row.iloc[0]["episode_dir"]), histogram, out_dir / "west_zone_histogram.png")
        )
    return files
