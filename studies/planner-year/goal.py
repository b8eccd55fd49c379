"""Issue 52's goal tables from a merged year-planner folder: each controller's sums over the five weathers' years
against the building's own controls (HVAC energy, the bill with its energy and demand parts, occupied K.h, the mean
share in its own bounds), one row per seed and one for the seeds' mean with their range.

    .venv/bin/python studies/planner-year/goal.py results/model-based/office-medium/year-planner \
        [--rule results/model-based/office-medium/rule-year/results.csv]

`--rule`: a rule-based controller's years on the same weathers (`evaluate --rbc`), shown as a row and as the
column "HVAC × the rule" (`--rule-name`: its row's name). Prints a Markdown table (the README's), nothing else.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import pandas as pd

from parallel_eplus.evaluation.controllers import BASELINE_LABEL

WEATHERS = ["CA", "CO", "FL", "IL", "VA"]
SUMMED = ["hvac_energy_kwh", "bill", "bill_energy", "bill_demand", "occupied_discomfort_kh"]


def totals(rows: pd.DataFrame) -> pd.Series:
    """Sums over the weathers' years (the mean for the share in bounds), with each weather's HVAC energy."""
    rows = rows.set_index("weather").loc[WEATHERS]  # a missing weather is a KeyError, never a silent short sum
    out = rows[SUMMED].sum()
    out["in_band_pct"] = rows["in_band_pct"].mean()
    for w in WEATHERS:
        out[f"hvac_{w}"] = rows.at[w, "hvac_energy_kwh"]
    return out


def table(results: pd.DataFrame, rule: pd.DataFrame | None, rule_name: str = "the rule alone") -> str:
    own = totals(results[results.controller == BASELINE_LABEL].drop_duplicates("weather"))
    rows = {"own controls": own}
    if rule is not None:
        rows[rule_name] = totals(rule[rule.controller != BASELINE_LABEL])
    learned = results[results.controller != BASELINE_LABEL]
    seeds = {f"{c} {str(r).rsplit('-', 1)[-1]}": totals(g) for (c, r), g in learned.groupby(["controller", "run"])}
    rows.update(seeds)
    head = ["controller", "HVAC energy × own (CA, CO, FL, IL, VA)"]
    head += ["HVAC × the rule"] if rule is not None else []
    head += ["bill × own", "energy charges × own", "demand charges × own", "occupied K·h", "in own bounds (mean)"]
    lines = ["| " + " | ".join(head) + " |", "|" + " --- |" * len(head)]

    def ratios(t: pd.Series) -> dict[str, float]:
        keys = ("hvac_energy_kwh", "bill", "bill_energy", "bill_demand")
        r = {k: t[k] / own[k] if own[k] else float("nan") for k in keys}
        r["rule"] = t["hvac_energy_kwh"] / rows[rule_name]["hvac_energy_kwh"] if rule is not None else 0.0
        return r

    def line(name: str, t: pd.Series, spread: dict[str, tuple[float, float]] | None = None) -> str:
        r = ratios(t)

        def cell(key: str, value: float, fmt: str = "×{:.3f}") -> str:
            if pd.isna(value):  # a tariff with no demand charges: 0 / 0
                return "–"
            text = fmt.format(value)
            if spread and key in spread:
                text += " [" + ", ".join(fmt.format(v).strip("× %") for v in spread[key]) + "]"
            return text

        per = ", ".join(f"{t[f'hvac_{w}'] / own[f'hvac_{w}']:.3f}" for w in WEATHERS)
        cells = [name, f"{cell('hvac_energy_kwh', r['hvac_energy_kwh'])} ({per})"]
        cells += [cell("rule", r["rule"])] if rule is not None else []
        cells += [cell(k, r[k]) for k in ("bill", "bill_energy", "bill_demand")]
        cells += [cell("occupied_discomfort_kh", t["occupied_discomfort_kh"], "{:.1f}"),
                  cell("in_band_pct", t["in_band_pct"], "{:.2f} %")]  # fmt: skip
        return "| " + " | ".join(cells) + " |"

    lines += [line(name, t) for name, t in rows.items()]
    if len(seeds) > 1:
        frame = pd.DataFrame(seeds).T
        each = {name: ratios(t) for name, t in seeds.items()}
        each = pd.DataFrame(each).T
        spread = {k: (each[k].min(), each[k].max()) for k in each.columns}
        spread.update({k: (frame[k].min(), frame[k].max()) for k in ("occupied_discomfort_kh", "in_band_pct")})
        lines.append(line(f"mean of {len(seeds)} seeds [min, max]", frame.mean(), spread))
    return "\n".join(lines)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("folder", type=Path, help="a merged year-planner folder (its results.csv)")
    p.add_argument("--rule", type=Path, help="a rule's results.csv over the same years")
    p.add_argument("--rule-name", default="the rule alone", help="its row's name")
    a = p.parse_args()
    rule = pd.read_csv(a.rule) if a.rule else None
    print(table(pd.read_csv(a.folder / "results.csv"), rule, a.rule_name))


if __name__ == "__main__":
    main()
