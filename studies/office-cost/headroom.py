"""How much of a building's electricity bill its HVAC can move at all: from the own controls' years (an `evaluate
--baseline` folder), per weather, the bill and its parts, HVAC's share of the energy charges, and the bill of the
same year with HVAC's electricity taken out of the meter, step by step (the lights, plugs and everything else
unchanged). That bill is a floor no supervisory controller reaches (it would run the HVAC for free), so
`1 - floor / own` bounds the saving any controller of the HVAC can make on the whole-building bill.

    .venv/bin/python studies/office-cost/headroom.py ../planner-year/office-small-cost/perfect/seed0 \
        --building results/model-based/office-small-cost/spec.toml

Prints a Markdown table (results/model-based/office-small-cost/year-planner/README.md's), nothing else.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import pandas as pd

from parallel_eplus.buildings.bill import monthly_bill
from parallel_eplus.buildings.building import load_building

WEATHERS = ["CA", "CO", "FL", "IL", "VA"]


def year(steps: pd.DataFrame, tariff, step_minutes: float) -> dict[str, float]:
    """One year's bill with and without HVAC's electricity, and their parts."""
    starts = list((steps["time"].dt.round("min") - pd.Timedelta(minutes=step_minutes)).dt.to_pydatetime())
    power = steps["power_w"].to_numpy(float)
    hvac = np.clip(steps["hvac_power_w"].to_numpy(float), 0, None)
    bills = {"own": monthly_bill(tariff, power, starts, step_minutes),
             "floor": monthly_bill(tariff, power - hvac, starts, step_minutes)}  # fmt: skip
    out = {f"{k}_{p}": sum(m[p] for m in b.values()) for k, b in bills.items() for p in ("energy", "demand")}
    kwh = hvac * step_minutes / 60 / 1000
    out["hvac_energy_charges"] = float(np.sum(kwh * tariff.series(starts)))
    out["hvac_kwh_share"] = float(hvac.sum() / np.clip(power, 0, None).sum())
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("folder", type=Path, help="an `evaluate --baseline` output folder (episodes/baseline/W/...)")
    parser.add_argument("--building", required=True, help="the spec whose [kpis] tariff prices the bill")
    args = parser.parse_args()
    building = load_building(args.building)
    tariff = building.comfort.kpis.tariffs["Electricity"]
    step_minutes = 24 * 60 / building.steps_per_day
    rows = {}
    for w in WEATHERS:
        (path,) = sorted((args.folder / "episodes" / "baseline" / w).glob("episode-*/steps.parquet"))
        rows[w] = year(pd.read_parquet(path, columns=["time", "power_w", "hvac_power_w"]), tariff, step_minutes)
    t = pd.DataFrame(rows).T
    t.loc["all five"] = t.sum()
    t.loc["all five", "hvac_kwh_share"] = t.loc[WEATHERS, "hvac_kwh_share"].mean()
    own = t.own_energy + t.own_demand
    floor = t.floor_energy + t.floor_demand
    head = ["weather", "own bill ($)", "energy charges", "demand charges", "HVAC's share of the meter's kWh",
            "HVAC's share of energy charges", "bill without HVAC × own", "of which demand charges × own"]
    print("| " + " | ".join(head) + " |\n|" + " --- |" * len(head))
    for w in t.index:
        share = "mean " if w == "all five" else ""
        print(f"| {w} | {own[w]:,.0f} | {t.own_energy[w]:,.0f} | {t.own_demand[w]:,.0f} | "
              f"{share}{t.hvac_kwh_share[w]:.1%} | {t.hvac_energy_charges[w] / t.own_energy[w]:.1%} | "
              f"×{floor[w] / own[w]:.3f} | ×{t.floor_demand[w] / t.own_demand[w]:.3f} |")  # fmt: skip


if __name__ == "__main__":
    main()
