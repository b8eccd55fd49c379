"""The electricity bill's parts in results.md: energy and demand charges per controller and weather, then per month
(buildings/pricing/bill.py computes them from each episode's step table; results.csv has every figure)."""

from __future__ import annotations

import re

import pandas as pd

MONTHS = ("Jan", "Feb", "Mar", "Apr", "May", "Jun", "Jul", "Aug", "Sep", "Oct", "Nov", "Dec")


def _months(df: pd.DataFrame) -> list[str]:
    return sorted({m.group(1) for c in df.columns if (m := re.fullmatch(r"bill_energy_(\d\d)", c))})


def bill_markdown(df: pd.DataFrame, baseline: str, shared: pd.DataFrame, note: str = "") -> str:
    """Per controller and weather: energy charges, demand charges, the bill and its ratio to the built-in controls'
    on the same weather, the highest 15-minute demand; then each month, averaged over `shared` (the rows of the
    weathers every controller finished, building_table.comparable, which says so in `note`)."""
    if "bill" not in df.columns:
        return ""
    base = df[df.controller == baseline].groupby("weather")["bill"].mean()
    lines = ["The electricity bill under the spec's tariff (the facility's meter: energy charges per kWh, demand "
             "charges per kW of each month's highest 15-minute demand; docs/kpis.md):", "",
             "| Controller | Weather | energy charges | demand charges | bill | × built-in | peak 15-min (kW) |",
             "|---|---|---|---|---|---|---|"]  # fmt: skip
    for _, r in df.iterrows():
        ref = base.get(r.weather)
        ratio = f"{r.bill / ref:.3f}" if ref else "–"
        lines.append(f"| {r.controller} | {r.weather} | {r.bill_energy:,.2f} | {r.bill_demand:,.2f} | {r.bill:,.2f} | "
                     f"{ratio} | {r.peak_15min_kw:,.1f} |")  # fmt: skip
    months = _months(df)
    if months:
        columns = [f"{k}_{m}" for m in months for k in ("bill_energy", "bill_demand", "peak_15min_kw")]
        avg = shared.groupby("controller", sort=False)[[c for c in columns if c in shared.columns]].mean()
        lines += ["", *([note] if note else []), "Per month, mean over the weathers:", "",
                  "| Controller | month | energy charges | demand charges | bill | peak 15-min (kW) |",
                  "|---|---|---|---|---|---|"]  # fmt: skip
        for c, r in avg.iterrows():
            for m in months:
                energy, demand = r.get(f"bill_energy_{m}"), r.get(f"bill_demand_{m}")
                if pd.isna(energy):
                    continue
                lines.append(f"| {c} | {MONTHS[int(m) - 1]} | {energy:,.2f} | {demand:,.2f} | {energy + demand:,.2f} | "
                             f"{r.get(f'peak_15min_kw_{m}', float('nan')):,.1f} |")  # fmt: skip
    return "\n".join(lines) + "\n"
