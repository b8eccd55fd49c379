"""Plain TRPO (CA-CO-FL) at the paper's budget: in-band % and power of each evaluated checkpoint against steps.

Reads the five-weather sweeps of the checkpoints under results/paper/paper-budget/<steps>/results.csv (and
the 1M-step model's rows in results/paper/results.csv), and draws them beside the paper's TRPO (CA-CO-FL)
and our built-in and rule-based controllers. Writes results/paper/paper-budget/curve.png and curve.md.

    .venv/bin/python studies/paper-budget/paper_budget_plot.py
"""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import pandas as pd  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]
OUT = ROOT / "results" / "paper" / "paper-budget"
WEATHERS = ["CA", "CO", "FL", "IL", "VA"]
PAPER = {"label": "paper: TRPO (CA-CO-FL), 300 episodes", "power_kw": 98.3, "in_band_pct": 99.6}


def _means(csv: Path, controller: str) -> tuple[float, float]:
    df = pd.read_csv(csv)
    rows = df[(df["controller"] == controller) & df["weather"].isin(WEATHERS)]
    if len(rows) != len(WEATHERS):
        raise ValueError(f"{csv}: {controller!r} lacks some of {WEATHERS}")
    return rows["in_band_pct"].mean(), rows["power_kw"].mean()


def checkpoints() -> pd.DataFrame:
    paper_csv = ROOT / "results" / "paper" / "results.csv"
    points = [(1_015_808, *_means(paper_csv, "TRPO (CA-CO-FL) 1M"))]
    for d in sorted(OUT.glob("[0-9]*"), key=lambda p: int(p.name)):
        df = pd.read_csv(d / "results.csv")
        points.append((int(d.name), *_means(d / "results.csv", df["controller"].iloc[0])))
    return pd.DataFrame(points, columns=["steps", "in_band_pct", "power_kw"])


def main() -> None:
    paper_csv = ROOT / "results" / "paper" / "results.csv"
    refs = {label: _means(paper_csv, label) for label in ("Baseline", "Rule-based")}
    curve = checkpoints()
    fig, (top, bottom) = plt.subplots(2, 1, figsize=(8, 7), sharex=True)
    top.plot(curve["steps"] / 1e6, curve["in_band_pct"], "o-", color="tab:blue", label="ours: TRPO (CA-CO-FL)")
    bottom.plot(curve["steps"] / 1e6, curve["power_kw"], "o-", color="tab:blue", label="ours: TRPO (CA-CO-FL)")
    for ax, key in ((top, "in_band_pct"), (bottom, "power_kw")):
        ax.axhline(PAPER[key], color="tab:red", linestyle="--", label=PAPER["label"])
        ax.axhline(refs["Baseline"][key == "power_kw"], color="grey", linestyle=":", label="built-in (EnergyPlus)")
        ax.axhline(refs["Rule-based"][key == "power_kw"], color="tab:green", linestyle=":", label="rule-based")
    top.set_ylabel("zone samples in 22-25 °C (%)")
    bottom.set_ylabel("mean total power (kW)")
    bottom.set_xlabel("environment steps (millions; 35,040 per full-year episode)")
    top.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8)
    fig.suptitle("Plain TRPO, paper's settings: five-weather mean, frozen deterministic policy")
    fig.tight_layout()
    fig.savefig(OUT / "curve.png", dpi=120, bbox_inches="tight")
    lines = [
        "| checkpoint (steps) | episodes | in 22-25 °C (%) | power (kW) | vs built-in |",
        "|---:|---:|---:|---:|---:|",
    ]
    base = refs["Baseline"][1]
    for r in curve.itertuples():
        change = 100 * (r.power_kw - base) / base
        lines.append(
            f"| {r.steps:,} | {r.steps / 35040:.0f} | {r.in_band_pct:.2f} | {r.power_kw:.1f} | {change:+.1f} % |"
        )
    (OUT / "curve.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
