"""Steps and wall-clock to issue 51's goal for the network trained through the model: every round's policy over
full years on the five weathers, per seed, and the first round that meets the goal (the mean energy change at or
below `--energy`, every weather's share in band at or above `--band`).

    .venv/bin/python studies/model-gradient/to_goal.py ROUNDS FINAL POLICIES RUNS OUT

- ROUNDS/seed<k>/results.csv: `evaluate` of the pilot's rounds 0..R-1 (labels "round <r>"), without the baseline;
- FINAL/results.csv: the committed full years of its last round (label "Through the model") and the built-in's;
- POLICIES/seed<k>/rounds.json: the pilot's log (its policy's steps so far, `starts`, and `wall_s` per round; a
  log without it leaves the wall-clock blank);
- RUNS/*-mpc-seed<k>/status.json: the planner run it started from (its steps and wall-clock).

A round counts everything simulated until its network had been checked on its training weeks: the planner's steps,
and the policy's and the building's own controls' weeks of every round up to it (the own controls' weeks only give
the pilot's per-round comparison, so the table also shows the steps without them). Writes OUT/to_goal.csv and
OUT/to_goal.md.
"""

from __future__ import annotations

import argparse
import json
import logging
from pathlib import Path

import numpy as np
import pandas as pd

from parallel_eplus.evaluation.controllers import BASELINE_LABEL
from parallel_eplus.evaluation.seeds import interval, with_changes

log = logging.getLogger("to-goal")
FINAL_LABEL = "Through the model"


def seed_of(run: str) -> int:
    return int(str(run).rsplit("seed", 1)[1])


def rounds_table(rounds: Path, final: Path, policies: Path, runs: Path) -> pd.DataFrame:
    """One row per (seed, round): its steps, wall-clock, energy change and worst weather's share in band."""
    done = pd.read_csv(final / "results.csv")
    baseline = done[done.controller == BASELINE_LABEL]
    parts = [done[done.controller == FINAL_LABEL].assign(seed=lambda d: d.run.map(seed_of))]
    for path in sorted(rounds.glob("seed*/results.csv")):
        part = pd.read_csv(path)
        parts.append(part[part.controller != BASELINE_LABEL].assign(seed=int(path.parent.name.removeprefix("seed"))))
    df = pd.concat(parts, ignore_index=True)
    logs = {s: json.loads((policies / f"seed{s}" / "rounds.json").read_text()) for s in df.seed.unique()}
    pairs = zip(df.seed, df.controller, strict=True)
    df["round"] = [len(logs[s]) - 1 if c == FINAL_LABEL else int(c.split()[-1]) for s, c in pairs]
    df = with_changes(pd.concat([baseline, df], ignore_index=True), BASELINE_LABEL)
    df = df[df.controller != BASELINE_LABEL].astype({"seed": int, "round": int})
    rows = []
    for (seed, r), group in df.groupby(["seed", "round"]):
        log_row = logs[seed][r]
        status = json.loads(next(runs.glob(f"*-mpc-seed{seed}/status.json")).read_text())
        rows.append({"seed": seed, "round": r, "energy_change_pct": group.energy_change_pct.mean(),
                     "worst_in_band_pct": group.in_band_pct.min(), "in_band_pct": group.in_band_pct.mean(),
                     "weathers": len(group), "all_weathers": len(group) == baseline.weather.nunique(),
                     "planner_steps": status["steps"], "planner_s": status["wall_s"],
                     "policy_steps": log_row["starts"], "pilot_s": log_row.get("wall_s", np.nan)})  # fmt: skip
    table = pd.DataFrame(rows).sort_values(["seed", "round"], ignore_index=True)
    table["steps"] = table.planner_steps + 2 * table.policy_steps
    table["training_steps"] = table.planner_steps + table.policy_steps
    table["wall_min"] = (table.planner_s + table.pilot_s) / 60
    return table


def first_at_goal(table: pd.DataFrame, band: float, energy: float) -> pd.DataFrame:
    met = table[(table.worst_in_band_pct >= band) & (table.energy_change_pct <= energy) & table.all_weathers]
    return met.groupby("seed").head(1).set_index("seed")


def report(table: pd.DataFrame, goal: pd.DataFrame, band: float, energy: float) -> str:
    lines = [
        f"# Steps to the goal: ≤ {energy:g} % energy, every weather ≥ {band:g} % in band (full years, 5 weathers)",
        "",
        "| seed | round | simulator steps (without the own controls' weeks) | wall-clock (min) | "
        "energy vs built-in | in band, worst weather | at goal |",
        "| --- | --- | --- | --- | --- | --- | --- |",
    ]
    for row in table.itertuples():
        at = "**yes**" if row.seed in goal.index and goal.loc[row.seed, "round"] == row.round else ""
        lines.append(
            f"| {row.seed} | {row.round} | {row.steps:,} ({row.training_steps:,}) | {row.wall_min:.1f} | "
            f"{row.energy_change_pct:+.1f} % | {row.worst_in_band_pct:.2f} % | {at} |"
        )
    lines += ["", f"Seeds at the goal: {len(goal)} of {table.seed.nunique()}."]
    if len(goal) == table.seed.nunique():
        for name, col, fmt in (("simulator steps", "steps", "{:,.0f}"), ("without the own controls' weeks",
                               "training_steps", "{:,.0f}"), ("wall-clock (min)", "wall_min", "{:.1f}")):  # fmt: skip
            point, low, high = interval([goal[col].to_numpy(float)])
            lines.append(
                f"- {name} to the goal: {fmt.format(point)} [{fmt.format(low)}, {fmt.format(high)}] "
                f"(seeds: {', '.join(fmt.format(v) for v in goal[col])})"
            )
    return "\n".join(lines) + "\n"


def main() -> None:
    logging.basicConfig(level=logging.INFO, format="%(message)s")
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    for name in ("rounds", "final", "policies", "runs", "out"):
        p.add_argument(name, type=Path)
    p.add_argument("--band", type=float, default=99.6, help="every weather's share in band at least this (%%)")
    p.add_argument("--energy", type=float, default=-22.0, help="the mean energy change at most this (%%)")
    args = p.parse_args()
    table = rounds_table(args.rounds, args.final, args.policies, args.runs)
    goal = first_at_goal(table, args.band, args.energy)
    args.out.mkdir(parents=True, exist_ok=True)
    table.to_csv(args.out / "to_goal.csv", index=False)
    (args.out / "to_goal.md").write_text(report(table, goal, args.band, args.energy))
    log.info("%s", (args.out / "to_goal.md").read_text())
    if np.isnan(table.energy_change_pct).any():
        log.warning("some rounds have no built-in year on their weather to compare with")


if __name__ == "__main__":
    main()
