"""report.md: the answer first (which controller, and why), then every candidate's figures on the training and the
held-out weathers, each read from results/<period>.csv beside it, the figures, and how the run was made (periods,
preset, training, time per stage), so a reader can check every number against the files."""

from __future__ import annotations

import os
from pathlib import Path

import pandas as pd

from parallel_eplus.optimize.choice import KH_ALLOWANCE, KH_ALLOWANCE_SHARE, METRIC_NAMES, MIN_SAVING, Choice
from parallel_eplus.optimize.figures import DAY_PNG, SAVINGS_PNG
from parallel_eplus.optimize.folders import STAGES, BuildingFolder
from parallel_eplus.optimize.periods import dates
from parallel_eplus.optimize.settings import QUICK, OptimizeSettings

CAPTIONS = {
    SAVINGS_PNG: "Each candidate against the own controls, summed over the test periods: filled on the held-out "
    "weathers, hollow on the training ones. A candidate is chosen left of the vertical dashed line (0.5 % lower) and "
    "at or below the horizontal one (+0.1 K·h, or 1 % of the own controls' K·h where that is more).",
    DAY_PNG: "Zone temperatures (lines), each zone's own thermostat bounds (green) and the controller's setpoints "
    "(dashed) over one day of the first held-out weather, under the own controls and the chosen controller (when the "
    "own controls are chosen, the candidate that came closest), from the evaluations' step records "
    "(eval/<candidate>/<period>/episodes/).",
}


def _x(v) -> str:
    return "" if v is None or pd.isna(v) else f"{v:.3f}"


def candidate_rows(train: pd.DataFrame, held: pd.DataFrame, facility: bool = False) -> list[str]:
    """The candidates' table; `facility`: with the facility's energy (a data center's measure) first."""
    columns = ("energy_kwh",) * facility + ("hvac_energy_kwh", "bill", "peak_15min_kw")
    heads = "facility energy × | " * facility + "HVAC energy × | bill × | peak ×"
    lines = [f"| candidate | weathers | {heads} | occupied K·h: own → it | in own bounds: own → it | periods |",
             "|---" * (5 + len(columns)) + "|"]  # fmt: skip
    for where, df in (("held-out", held), ("training", train)):
        for _, r in df.iterrows():
            ratios = " | ".join(_x(r.get(f"{c}_x")) for c in columns)
            comfort = f"{r.kh_own:.2f} → {r.kh:.2f} | {r.in_band_pct_own:.2f} % → {r.in_band_pct:.2f} %"
            lines.append(f"| {r.label} | {where} | {ratios} | {comfort} | {r.pairs} of {r.own_pairs} |")
    return lines


def write_report(folder: BuildingFolder, settings: OptimizeSettings, metric_key: str, train: pd.DataFrame,
                 held: pd.DataFrame,
                 choice: Choice | None, periods: dict, figures: list[str], notes: list[str]) -> str:  # fmt: skip
    status = folder.status()
    stages = status.get("stages", {})
    exported = stages.get("export", {})
    metric = METRIC_NAMES[metric_key]
    lines = [f"# {folder.name}: what it can save, and which controller to install", ""]
    if settings.quick:
        lines += [
            "> **`--quick`**: a smoke run of every stage, not a result: one fixed winter window (January 11-12) "
            "instead of BOPTEST's four periods, 2-day training episodes and a few hundred training steps.",
            "",
        ]
    if choice is None:
        lines += ["**No choice yet**: not every candidate is scored (rerun the same command to continue).", ""]
    else:
        lines += [f"**Chosen: {choice.label}.** {choice.reason[0].upper()}{choice.reason[1:]}.", ""]
        written = exported.get("written") and Path(os.path.relpath(exported["written"], folder.root)).as_posix()
        if written and choice.candidate == "learned":  # beside the report: the link holds wherever the folder goes
            lines += [f"Written: [{written}]({written}) (`parallel-eplus export`: the controller with its contract); "
                      f"serve it with `parallel-eplus serve {folder.controller}` (docs/deploy.md).", ""]  # fmt: skip
        elif written:
            lines += [f"Written: [{written}]({written}) ({exported.get('note')}).", ""]
        elif exported.get("state") == "done":
            lines += ["No controller written: keep your own controls (nothing was found that does better on weathers "
                      "it never saw).", ""]  # fmt: skip
        elif exported.get("state") == "failed":
            lines += [f"The export failed: {exported.get('error')}", ""]
    lines += ["## Every candidate", "",
              f"Sums over the test periods (peak: the highest 15-minute mean), as ratios to the own controls' on the "
              f"same periods and weathers (× own; 1.000: the same). Held-out weathers ({', '.join(settings.held_out)}) "
              f"decide; training weathers ({', '.join(settings.weathers)}) are shown beside them. The bill is the "
              "facility's electricity under the spec's tariff (docs/kpis.md). Read from `results/*.csv`.", "",
              *candidate_rows(train, held, metric_key == "energy_kwh"), ""]  # fmt: skip
    if choice is not None:
        lines += ["## The choice", "",
                  f"By the held-out weathers only: the lowest {metric} among the candidates at no more occupied "
                  f"discomfort than the own controls (at most their K·h + max({KH_ALLOWANCE} K·h, "
                  f"{100 * KH_ALLOWANCE_SHARE:.0f} %)) and at least {100 * MIN_SAVING:.1f} % lower than theirs; "
                  "otherwise the own controls (do no harm).", ""]  # fmt: skip
        labels = dict(zip(held.candidate, held.label, strict=True)) if not held.empty else {}
        lines += [f"- {labels.get(key, key)}: {why}" for key, why in choice.verdicts.items()] + [""]
    if notes:
        lines += ["## Not scored, or refused", "", *[f"- {n}" for n in notes], ""]
    if figures:
        lines += ["## Figures", ""]
        for f in figures:
            lines += [f"![{f}]({f})", "", CAPTIONS.get(f, ""), ""]
    lines += ["## How it was made", "", f"- Source: `{folder.source}`; {stages.get('prepare', {}).get('how', '')}.",
              f"- Actions: {', '.join(stages.get('prepare', {}).get('actions', []))}.",
              f"- Test periods: {stages.get('periods', {}).get('how', '')}."]  # fmt: skip
    train_stage = stages.get("train", {})
    if train_stage.get("state") == "done":
        cut = " (stopped at its share of the budget)" if train_stage.get("stopped") else ""
        lines.append(f"- Learned controller: preset `{train_stage['preset']}` (version {train_stage.get('version')}: "
                     f"{train_stage.get('summary', '').rstrip('.')}), {train_stage.get('steps', 0):,} of "
                     f"{train_stage.get('planned') or 0:,} steps{cut} on {', '.join(settings.weathers)}; command in "
                     "`logs/train.log`, run in `runs/learned/`.")  # fmt: skip
    spent = [f"{s} {stages[s]['seconds'] / 60:.1f}" for s in STAGES if stages.get(s, {}).get("seconds")]
    lines.append(f"- Time (minutes): {', '.join(spent)}; {status.get('spent_s', 0) / 60:.1f} in all of "
                 f"{settings.budget_minutes:g} budgeted, over {status.get('sessions', 1)} session(s).")  # fmt: skip
    lines += ["", "| period | weather | scored from | to |", "|---|---|---|---|"]
    for name, w, first, last in dates(periods):
        lines.append(f"| {'quick window' if name == QUICK else name} | {w} | {first:%b %d} | {last:%b %d} |")
    text = "\n".join(lines) + "\n"
    folder.report.write_text(text)
    return text
