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


def _change(value: float, base: float | None) -> str:
    return "–" if base is None or not base else f"{100 * (value / base - 1):+.1f} %"


def table_markdown(df: pd.DataFrame, baseline: str) -> str:
    """Per weather and on average: energy (every fuel the spec meters) against the baseline, peak electric power,
    thermal discomfort (K·h per zone) and the share of zone samples in band, where the band applies."""
    zones = [c.removesuffix("_in_band_pct") for c in df.columns if c.endswith("_in_band_pct") and c != "in_band_pct"]
    band = band_of(df)
    named = "in band" if band is None else "in {:g}–{:g} °C".format(*band)
    kpis = "energy_kwh" in df.columns  # summaries from before the BOPTEST figures have power only
    energy = "energy_kwh" if kpis else "power_kw"
    base = df[df.controller == baseline].set_index("weather")[energy]
    head = "| Controller | Weather | power (kW) | "
    head += "energy (kWh) | vs baseline | peak (kW) | discomfort (K·h/zone) | " if kpis else "vs baseline | "
    width = 5 + 3 * kpis + len(zones)
    lines = [head + " | ".join(f"{z} {named}" for z in zones) + f" | all {named} |", "|---" * width + "|"]
    for _, r in df.iterrows():
        change = "–" if r.controller == baseline else _change(r[energy], base.get(r.weather))
        cells = [f"{r.power_kw:.2f}"]
        cells += (
            [f"{r.energy_kwh:,.0f}", change, f"{r.peak_power_kw:.1f}", f"{r.discomfort_kh:.1f}"] if kpis else [change]
        )
        cells += [f"{r[f'{z}_in_band_pct']:.2f} %" for z in zones] + [f"{r.in_band_pct:.2f} %"]
        lines.append(f"| {r.controller} | {r.weather} | " + " | ".join(cells) + " |")
    shared, note = comparable(df)
    columns = ["power_kw", "in_band_pct"] + (["energy_kwh", "peak_power_kw", "discomfort_kh"] if kpis else [])
    avg = shared.groupby("controller", sort=False)[columns].mean()
    lines += ["", *([note] if note else [])]
    if kpis:
        lines += [f"| Controller | mean power (kW) | energy per weather (kWh) | vs baseline | peak (kW) | "
                  f"discomfort (K·h/zone) | all {named} |", "|---|---|---|---|---|---|---|"]  # fmt: skip
    else:
        lines += [f"| Controller | mean power (kW) | vs baseline | all {named} |", "|---|---|---|---|"]
    for c, r in avg.iterrows():
        change = "–" if c == baseline or baseline not in avg.index else _change(r[energy], avg[energy][baseline])
        if kpis:
            cells = [f"{r.power_kw:.2f}", f"{r.energy_kwh:,.0f}", change, f"{r.peak_power_kw:.1f}",
                     f"{r.discomfort_kh:.1f}"]  # fmt: skip
        else:
            cells = [f"{r.power_kw:.2f}", change]
        lines.append(f"| {c} | " + " | ".join(cells) + f" | {r.in_band_pct:.2f} % |")
    if kpis and "comfort_steps_pct" in df.columns and (df["comfort_steps_pct"] < 100).any():
        share = df["comfort_steps_pct"].mean()
        lines += ["", f"Comfort figures count the samples where the band applies ({share:.1f} % of steps); "
                  "energy and power count every step."]  # fmt: skip
    if "hvac_energy_kwh" in df.columns:
        lines += ["", boptest_markdown(df, baseline)]
    if "bill" in df.columns:
        from parallel_eplus.evaluation.bill_table import bill_markdown

        lines += ["", bill_markdown(df, baseline, *comparable(df))]
    return "\n".join(lines) + "\n"


# (summary key, header, format): BOPTEST's figures (docs/kpis.md); those with a ratio get "× built-in" beside them
BOPTEST = (
    ("hvac_energy_kwh_m2", "HVAC energy (kWh/m²)", "{:.2f}", True),
    ("energy_kwh_m2", "facility energy (kWh/m²)", "{:.2f}", True),
    ("cost_m2", "cost (/m²)", "{:.3f}", True),
    ("emissions_kg_m2", "emissions (kg CO2e/m²)", "{:.3f}", True),
    ("discomfort_kh", "discomfort (K·h/zone)", "{:.1f}", False),
    ("in_band_pct", "in own bounds", "{:.2f} %", False),
)


RATIOS = ("hvac_energy_kwh", "energy_kwh", "cost", "emissions_kg", "discomfort_kh", "bill", "peak_15min_kw")


def with_ratios(df: pd.DataFrame, baseline: str) -> pd.DataFrame:
    """`<figure>_vs_builtin` columns: each BOPTEST figure over the built-in controls' mean on the same weather."""
    if baseline not in set(df["controller"]):
        return df
    df = df.copy()
    base = df[df.controller == baseline].groupby("weather")
    for key in (k for k in RATIOS if k in df.columns):
        df[f"{key}_vs_builtin"] = df[key] / df["weather"].map(base[key].mean())
    return df


def boptest_markdown(df: pd.DataFrame, baseline: str) -> str:
    """BOPTEST's figures per controller and weather, each beside its ratio to the built-in controls (CityLearn's
    normalization: 1.00 is the built-in's own), then averaged over the weathers every controller finished."""
    df = df.copy()
    if "floor_area_m2" not in df.columns:  # summaries without the model's floor area: totals, not per m²
        for key, *_ in BOPTEST:
            if key.endswith("_m2") and key.removesuffix("_m2") in df.columns:
                df[key] = df[key.removesuffix("_m2")]
    peaks = [c for c in df.columns if c.startswith("hvac_") and c.endswith("_peak_kw_m2")]
    cols = [b for b in BOPTEST if b[0] in df.columns]
    head = ["Controller", "Weather"]
    for _key, name, _, ratio in cols:
        head += [name, "× built-in"] if ratio else [name]
    head += [f"HVAC peak {c.removeprefix('hvac_').removesuffix('_peak_kw_m2')} (W/m²)" for c in peaks]
    area = (
        df["floor_area_m2"].dropna().iloc[0]
        if "floor_area_m2" in df.columns and df["floor_area_m2"].notna().any()
        else None
    )
    lines = [
        "BOPTEST's figures (docs/kpis.md)"
        + (f", per m² of the model's {area:,.0f} m² floor" if area else "")
        + "; × built-in: the ratio to the building's own controls on the same weather (CityLearn's form):",
        "",
        "| " + " | ".join(head) + " |",
        "|---" * len(head) + "|",
    ]
    base = df[df.controller == baseline].set_index("weather")

    def row(label: str, weather: str, r, ref) -> str:
        cells = [label, weather]
        for key, _, fmt, ratio in cols:
            cells.append(fmt.format(r[key]))
            if ratio:
                b = None if ref is None else ref.get(key)
                cells.append(f"{r[key] / b:.3f}" if b else "–")
        cells += [f"{1000 * r[c]:.1f}" for c in peaks]
        return "| " + " | ".join(cells) + " |"

    for _, r in df.iterrows():
        ref = base.loc[r.weather] if r.weather in base.index else None
        lines.append(row(r.controller, r.weather, r, ref))
    shared, _ = comparable(df)
    keys = [b[0] for b in cols] + peaks
    avg = shared.groupby("controller", sort=False)[keys].mean()
    ref = avg.loc[baseline] if baseline in avg.index else None
    for c, r in avg.iterrows():
        lines.append(row(f"**{c}**", "average", r, ref))
    return "\n".join(lines) + "\n"


def write_results(
    df: pd.DataFrame, out_dir: Path, baseline: str, full: pd.DataFrame | None = None, across: pd.DataFrame | None = None
) -> list[Path]:
    """`df`: one row per controller and weather (runs averaged); `full`: every run's rows; `across`: the seed
    table (seeds.py) of controllers with several runs."""
    from parallel_eplus.evaluation import seeds

    full = with_ratios(df if full is None else full, baseline)
    out_dir.mkdir(parents=True, exist_ok=True)
    full.to_csv(out_dir / "results.csv", index=False)
    extra = seeds.seeds_markdown(across) if across is not None else ""
    (out_dir / "results.md").write_text("# Evaluation\n\n" + table_markdown(df, baseline) + extra)
    files = [out_dir / "results.csv", out_dir / "results.md"]
    if across is not None and not across.empty:
        across.to_csv(out_dir / "seeds.csv", index=False)
        files.append(out_dir / "seeds.csv")
    return files + figures(df, out_dir, full)


def figures(df: pd.DataFrame, out_dir: Path, full: pd.DataFrame | None = None) -> list[Path]:
    """The building's own figures: its zones against its band, its power; no data-center references."""
    from parallel_eplus.evaluation import plots

    files = []
    if plots.zones_of(df):
        files.append(
            plots.temperature_comparison(df, out_dir / "temperatures.png", band_of(df) or plots.COMFORT_BAND_C)
        )
    files.append(plots.power_comparison(df, out_dir / "power.png", full))
    return files
