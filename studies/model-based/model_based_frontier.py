"""The energy-comfort frontier of one building's evaluation (issue 38): every controller's runs as points.

    python studies/model-based/model_based_frontier.py results/model-based/datacenter-2zone/jan [more folders] [--hvac]

Reads each folder's results.csv (`evaluate`'s), averages each run over the weathers, and plots energy against
the built-in controls (x) and the share of comfort samples in band (y), one marker per controller, one point per
run (seed), the built-in and rule-based controllers as points. Writes frontier.png beside each results.csv.
"""

from __future__ import annotations

import argparse
import logging
import sys
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import pandas as pd  # noqa: E402

from parallel_eplus.evaluation.seeds import with_changes  # noqa: E402

log = logging.getLogger("frontier")
BASELINE = "Baseline"
MARKERS = {"Baseline": "s", "Rule-based": "D", "Planner": "o", "Distilled": "^", "Recipe": "v"}


def frontier(folder: Path, hvac: bool = False) -> Path:
    df = pd.read_csv(folder / "results.csv")
    df = with_changes(df, BASELINE)
    comfort = "in_band_pct" if "in_band_pct" in df else next(c for c in df if c.endswith("in_band_pct"))
    energy = "hvac_energy_change_pct" if hvac else "energy_change_pct"
    per_run = df.groupby(["controller", "run"], dropna=False)[[energy, comfort]].mean().reset_index()
    fig, ax = plt.subplots(figsize=(6.4, 4.4))
    for label, runs in per_run.groupby("controller", sort=False):
        ax.scatter(runs[energy], runs[comfort], marker=MARKERS.get(str(label), "o"), s=46,
                   label=f"{label} ({len(runs)} run{'s' if len(runs) > 1 else ''})", alpha=0.85)  # fmt: skip
    what = "HVAC energy" if energy.startswith("hvac") else "energy"
    ax.set_xlabel(f"{what} vs built-in controls (%), mean over weathers")
    ax.set_ylabel(f"{comfort.replace('_pct', '').replace('_', ' ')} (%)")
    weathers = ", ".join(dict.fromkeys(df["weather"].astype(str)))
    ax.set_title(f"{folder.parent.name}, {folder.name}: {weathers}", fontsize=10)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8, loc="best")
    fig.tight_layout()
    out = folder / "frontier.png"
    fig.savefig(out, dpi=120)
    plt.close(fig)
    return out


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("folders", type=Path, nargs="+")
    p.add_argument("--hvac", action="store_true", help="HVAC energy (BOPTEST's, the office goal's) on x, not all")
    args = p.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(message)s")
    for folder in args.folders:
        log.info("written: %s", frontier(folder, args.hvac))
    return 0


if __name__ == "__main__":
    sys.exit(main())
