"""How much of a building's electricity bill its HVAC can move at all: from the own controls' years (an `evaluate
--baseline` folder), per weather, the bill and its parts, HVAC's share of the meter and of the energy charges, and
the same year's bill with part of HVAC's electricity taken off the meter, step by step (lights, plugs and the rest
unchanged):

- without HVAC: all of it. A floor no supervisory controller reaches (the HVAC would run for free), so
  `1 - floor / own` bounds the saving any controller of the HVAC can make on the whole-building bill;
- without conditioning: what HVAC draws above its fans' constant draw while it runs. The fans' draw is estimated as
  the median HVAC electric power over the running steps whose zones are all at least 0.3 K inside their own bounds
  (no zone calls for heating or cooling: the fans alone). Thermostats move the conditioning (here the cooling
  coils' compressors; the heating is gas, off the electricity bill); the fans run while the building's HVAC
  schedule says so, whatever the setpoints, so this floor bounds what thermostat actions can save.

    .venv/bin/python studies/office-cost/headroom.py ../planner-year/office-small-cost/perfect/seed0 \
        --building results/model-based/office-small-cost/spec.toml

Prints a Markdown table (results/model-based/office-small-cost/year-planner/README.md's), nothing else.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import pandas as pd

from parallel_eplus.buildings.building import load_building
from parallel_eplus.buildings.pricing.bill import monthly_bill

WEATHERS = ["CA", "CO", "FL", "IL", "VA"]
INSIDE_K = 0.3  # a zone this far inside both of its bounds calls for neither heating nor cooling


def fans_w(steps: pd.DataFrame, zones: list[str], bounds: tuple[tuple[str, str], ...]) -> float:
    """The fans' constant draw: the median HVAC electric power over running steps with no zone calling."""
    running = steps["hvac_power_w"] > 1.0
    quiet = np.ones(len(steps), bool)
    for zone, (lower, upper) in zip(zones, bounds, strict=True):
        quiet &= (steps[zone] > steps[lower] + INSIDE_K) & (steps[zone] < steps[upper] - INSIDE_K)
    return float(steps.loc[running & quiet, "hvac_power_w"].median())


def year(steps: pd.DataFrame, tariff, step_minutes: float, fans: float) -> dict[str, float]:
    """One year's bill with and without HVAC's electricity (or its conditioning part), and their parts."""
    starts = list((steps["time"].dt.round("min") - pd.Timedelta(minutes=step_minutes)).dt.to_pydatetime())
    power = steps["power_w"].to_numpy(float)
    hvac = np.clip(steps["hvac_power_w"].to_numpy(float), 0, None)
    conditioning = np.clip(hvac - fans, 0, None)
    bills = {"own": monthly_bill(tariff, power, starts, step_minutes),
             "no_hvac": monthly_bill(tariff, power - hvac, starts, step_minutes),
             "no_cond": monthly_bill(tariff, power - conditioning, starts, step_minutes)}  # fmt: skip
    out = {f"{k}_{p}": sum(m[p] for m in b.values()) for k, b in bills.items() for p in ("energy", "demand")}
    kwh = hvac * step_minutes / 60 / 1000
    out["hvac_energy_charges"] = float(np.sum(kwh * tariff.series(starts)))
    out["hvac_kwh_share"] = float(hvac.sum() / np.clip(power, 0, None).sum())
    out["fans_kw"] = fans / 1000
    out["fans_share"] = float(1 - conditioning.sum() / hvac.sum())
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("folder", type=Path, help="an `evaluate --baseline` output folder (episodes/baseline/W/...)")
    parser.add_argument("--building", required=True, help="the spec whose [kpis] tariff prices the bill")
    args = parser.parse_args()
    building = load_building(args.building)
    tariff = building.comfort.kpis.tariffs["Electricity"]
    step_minutes = 24 * 60 / building.steps_per_day
    zones, bounds = list(building.temperatures), building.zone_bounds
    rows = {}
    for w in WEATHERS:
        (path,) = sorted((args.folder / "episodes" / "baseline" / w).glob("episode-*/steps.parquet"))
        steps = pd.read_parquet(path)
        rows[w] = year(steps, tariff, step_minutes, fans_w(steps, zones, bounds))
    t = pd.DataFrame(rows).T
    t.loc["all five"] = t.sum()
    for mean in ("hvac_kwh_share", "fans_kw", "fans_share"):
        t.loc["all five", mean] = t.loc[WEATHERS, mean].mean()
    own = t.own_energy + t.own_demand
    head = [
        "weather",
        "own bill ($)",
        "energy charges",
        "demand charges",
        "HVAC's share of the meter's kWh",
        "HVAC's share of energy charges",
        "fans' draw (kW)",
        "fans' share of HVAC kWh",
        "bill without HVAC × own",
        "bill without conditioning × own",
    ]
    print("| " + " | ".join(head) + " |\n|" + " --- |" * len(head))
    for w in t.index:
        m = "mean " if w == "all five" else ""
        print(f"| {w} | {own[w]:,.0f} | {t.own_energy[w]:,.0f} | {t.own_demand[w]:,.0f} | "
              f"{m}{t.hvac_kwh_share[w]:.1%} | "
              f"{t.hvac_energy_charges[w] / t.own_energy[w]:.1%} | {m}{t.fans_kw[w]:.2f} | {m}{t.fans_share[w]:.1%} | "
              f"×{(t.no_hvac_energy[w] + t.no_hvac_demand[w]) / own[w]:.3f} | "
              f"×{(t.no_cond_energy[w] + t.no_cond_demand[w]) / own[w]:.3f} |")  # fmt: skip


if __name__ == "__main__":
    main()
