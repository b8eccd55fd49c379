"""The prototypes study's report: each building's figures as ratios to its own controls, the table a reader wants,
and the figure (savings against discomfort, one point per building)."""

from __future__ import annotations

import os
from pathlib import Path

import pandas as pd
from recipes import FALLBACK, IN_DEMAND, ON_RULE, OTHERS, PLAYED
from study import SCENARIOS, Study, finished, models, read_status, results_folder, scored, short_name, spec_of


def ratios(folder: Path) -> dict | None:
    """The planner's figures over the four scenarios and five weathers, each as a ratio to the building's own."""
    frames = [
        pd.read_csv(folder / f"{s}.csv").copy().assign(scenario=s)  # copy: one block, not one per column
        for s in SCENARIOS
        if (folder / f"{s}.csv").is_file()
    ]
    if len(frames) < len(SCENARIOS):
        return None
    df = pd.concat(frames)
    own, learned = df[df.controller == "Baseline"], df[df.controller != "Baseline"].fillna({"run": ""})
    figures = {}
    for column, how in (("hvac_energy_kwh", "sum"), ("bill", "sum"), ("peak_15min_kw", "max"),
                        ("occupied_discomfort_kh", "sum")):  # fmt: skip
        if column not in df:
            continue
        base = own[column].agg(how)
        per_run = learned.groupby("run")[column].agg(how)  # each seed's planner; their mean
        ratio = per_run / base if base else per_run * float("nan")
        figures[column] = ratio.mean()
        figures[f"{column}_own"] = base
        figures[f"{column}_learned"] = per_run.mean()
        if len(per_run) > 1:  # several seeds: their range beside the mean (one seed is an anecdote)
            figures |= {
                f"{column}_lo": ratio.min(),
                f"{column}_hi": ratio.max(),
                f"{column}_learned_lo": per_run.min(),
                f"{column}_learned_hi": per_run.max(),
            }
    figures["in_band_pct"] = learned.in_band_pct.mean()
    figures["in_band_pct_own"] = own.in_band_pct.mean()
    return figures


def _x(value: float) -> str:
    return "" if pd.isna(value) else f"{value:.3f}"


def _spread(r: pd.Series, column: str, digits: int = 3) -> str:
    """A figure with its seeds' range where several planners were scored."""
    value, lo, hi = (r.get(c, float("nan")) for c in (column, f"{column}_lo", f"{column}_hi"))
    if pd.isna(value):
        return ""
    return f"{value:.{digits}f}" + ("" if pd.isna(lo) else f" [{lo:.{digits}f}, {hi:.{digits}f}]")


def markdown(df: pd.DataFrame, study: Study) -> str:
    """The table a reader wants: every building, its figures as ratios to its own controls, or why it has none."""
    every = len(df) == len(models())  # else the rows asked for (`table NAMES`): the seeds' buildings
    lines = ["# Every DOE reference prototype, scored" if every else f"# {', '.join(df.building)}: scored", "",
             "Made by `python studies/prototypes/prototypes.py table` (the study: studies/prototypes/README.md). Each",
             "row is one model of the EnergyPlus wheel taken as a new user takes it: `building init`, the starter's",
             f"recommended actions, `building check`, the planner's recipe (`--recipe {study.played or study.recipe}`"
             + (f": `{study.recipe}`'s planners played with `{PLAYED[study.played][1]}`" if study.played else "")
             + ") on CA, CO and",
             f"FL ({study.steps:,} steps, seeds {', '.join(map(str, study.seeds))}), then `evaluate` on BOPTEST's four",
             "scenarios (peak and typical heating and cooling fortnights) on all five weathers (IL and VA held out).",
             "Ratios are the planner's over its own controls' (× built-in, CityLearn's form), summed over the 20",
             "fortnights (peak: the highest 15-minute mean); the bill under the example tariff with demand charges.",
             *(["With several seeds, a figure is their planners' mean and [lowest, highest]."]
               if len(study.seeds) > 1 else []),
             *([f"Where the recipe does not apply ({_why_not(study)}), the row is `{FALLBACK}`'s, the same",
                f"planner ([the `{FALLBACK}` table]({os.path.relpath(study.fallback, study.out)}/README.md))."]
               if _why_not(study) else []),
             "", "| building | actions | supply-air loops | HVAC energy × | bill × | peak × "
             "| occupied K·h: own → planner | in own bounds: own → planner | stage |",
             "|---|---|---|---|---|---|---|---|---|"]  # fmt: skip
    for _, r in df.iterrows():
        kh = in_band = ""
        if not pd.isna(r.get("hvac_energy_kwh", float("nan"))):
            kh = f"{r.occupied_discomfort_kh_own:.1f} → {_spread(r, 'occupied_discomfort_kh_learned', 1)}"
            in_band = f"{r.in_band_pct_own:.2f} % → {r.in_band_pct:.2f} %"
        stage = r.stage + (f": {r.reason}" if r.reason else "")
        figures = " | ".join(_spread(r, c) for c in ("hvac_energy_kwh", "bill", "peak_15min_kw"))
        lines.append(
            f"| {r.building} | {r.actions} | {r['supply-air loops']} | {figures} | {kh} | {in_band} | {stage} |"
        )
    done = df.dropna(subset=["hvac_energy_kwh"]) if "hvac_energy_kwh" in df else df.iloc[:0]
    if len(done):
        saves = ((done.hvac_energy_kwh < SAVES) | (done.get("bill", 1) < SAVES)).sum()
        holds = (done.occupied_discomfort_kh_learned <= done.occupied_discomfort_kh_own + SAME_KH).sum()
        lower = f"HVAC energy or bill at least {100 * (1 - SAVES):.1f} % lower"
        lines += ["", f"Scored: {len(done)} of {len(df)}. {lower}: {saves}; no more occupied",
                  f"discomfort than its own controls: {holds} (to {SAME_KH} K·h"
                  + ("; goal: all, savings on 12 of 16)." if every else ")."),
                  "",
                  "Why the planner finds so little, building by building, and what was tried: [the study's record]"
                  f"({_record(study.out)}#every-doe-prototype-2026-11-28-started)."]  # fmt: skip
    if (study.out / "savings.png").is_file():
        lines += ["", "![savings against discomfort](savings.png)"]
    lines += [*seeds_lines(study), *played_lines(study)] if every else []
    lines += rule_lines(df, study)
    return "\n".join(lines) + "\n"


def seeds_lines(study: Study) -> list[str]:
    """Pointers to the tables of the buildings scored over several seeds (`--seeds 0,1,2 --out OUT/RECIPE-seeds`)."""
    tables = sorted((study.fallback or study.out).glob("*-seeds/prototypes.csv"))
    if not tables:
        return []
    links = [f"{', '.join(pd.read_csv(t).building)} ([{t.parent.name}]({os.path.relpath(t.parent, study.out)}"
             "/README.md))" for t in tables]  # fmt: skip
    return ["", f"Over several seeds, each figure with their range: {'; '.join(links)}."]


def played_lines(study: Study) -> list[str]:
    """Pointers to the other played recipes' tables (`--recipe NAME`, OUT/NAME/), each with what it plays."""
    links = [f"[`{name}`]({name}/README.md) (`{PLAYED[name][0]}` with `{PLAYED[name][1]}`)"
             for name in OTHERS if (study.out / name / "README.md").is_file()]  # fmt: skip
    return ["", f"The other recipes' tables, each on the buildings it ran on: {'; '.join(links)}."] if links else []


MEASURES = ("rule", "ventilation", "rule-ventilation", "margin-ventilation")  # OUT/<name>/<folder>/: measures.py


def measure_rows(df: pd.DataFrame, study: Study, folder: str) -> list[str]:
    """A measure without learning (OUT/<name>/<folder>/: `evaluate --rbc`) per building, beside the planner's HVAC
    ratio."""
    rows = []
    for _, r in df.iterrows():
        figures = ratios((study.fallback or study.out) / r.building / folder)
        if figures is None:
            continue
        rows.append(f"| {r.building} | {_x(figures['hvac_energy_kwh'])} | {_x(figures.get('bill'))} | "
                    f"{_x(figures.get('peak_15min_kw'))} | {figures['occupied_discomfort_kh_own']:.1f} → "
                    f"{figures['occupied_discomfort_kh_learned']:.1f} | {figures['in_band_pct_own']:.2f} % → "
                    f"{figures['in_band_pct']:.2f} % | {_x(r.get('hvac_energy_kwh'))} |")  # fmt: skip
    return rows


def _measure_table(rows: list[str], who: str) -> list[str]:
    return [f"| building | HVAC energy × | bill × | peak × | occupied K·h: own → {who} | in own bounds: own → {who} "
            "| planner's HVAC × |", "|---|---|---|---|---|---|---|", *rows]  # fmt: skip


def rule_lines(df: pd.DataFrame, study: Study) -> list[str]:
    """The buildings whose air loops the starter takes over, Guideline 36's supply-air reset on them (`prototypes.py
    rule`: `evaluate --rbc`, the thermostats on their own schedules), and the outdoor air on demand where the model
    holds a fixed minimum (`prototypes.py ventilation`), each beside the planner's HVAC ratio."""
    lines = []
    rows = measure_rows(df, study, "rule")
    if rows:
        lines += ["", "## The air side without learning: Guideline 36's supply-air reset", "",
                  "`prototypes.py rule`: the buildings whose starter takes over supply air, `evaluate --rbc` with",
                  "`parallel_eplus.buildings.rules.air_reset:SupplyAirReset` named in the spec",
                  "(ASHRAE Guideline 36's reset",
                  "of the supply air on outdoor air and the zones' cooling requests; every thermostat on its own",
                  "schedule), on the same 20 fortnights. Ratios to the building's own controls as above; the last",
                  "column is the planner's.", "", *_measure_table(rows, "rule"), *ruled_lines(study)]  # fmt: skip
    rows = measure_rows(df, study, "ventilation")
    if rows:
        lines += ["", "## The outdoor air on demand, without learning", "",
                  "`prototypes.py ventilation`: every building whose model holds a fixed minimum of outdoor air, its",
                  'spec with `ventilation = "demand"` (each outdoor-air controller\'s flow follows the people present:',
                  "EnergyPlus's demand-controlled ventilation in the copy, docs/buildings.md) and",
                  "`parallel_eplus.buildings.rules.on_demand:OnDemand` (every action released to the building's own",
                  "controls), on the same 20 fortnights; its own controls' rows are the table's. Ratios to the",
                  "building's own controls as above; the last column is the planner's.", "",
                  *_measure_table(rows, "on demand")]  # fmt: skip
        both = measure_rows(df, study, "rule-ventilation")
        if both:
            lines += ["", "With Guideline 36's reset too (the spec naming `SupplyAirReset`, with",
                      '`ventilation = "demand"`), where the starter takes over supply air:', "",
                      *_measure_table(both, "both")]  # fmt: skip
        margin = measure_rows(df, study, "margin-ventilation")
        if margin:
            lines += ["", "With each thermostat 0.02 K inside its own schedule (the spec naming",
                      "`parallel_eplus.buildings.rules.own_margin:OwnMargin`, with `ventilation = \"demand\"`),",
                      "where every",
                      "action has a schedule of the building's own: the comfort the measure costs, bought back.", "",
                      *_measure_table(margin, "margin")]  # fmt: skip
        lines += best_lines(df, study) if len(df) == len(models()) else []  # the goal's count: every row
    return lines


def best_lines(df: pd.DataFrame, study: Study) -> list[str]:
    """The goal counted over what the service offers each building: the planner (this table's, and every played
    recipe's where it ran: on the reset, in the on-demand copy, with a margin), the reset and the outdoor air on
    demand, a building counting where any of them saves."""
    saves, holds = set(), set()
    base = study.fallback or study.out
    for _, r in df.iterrows():
        options = [(r.get("hvac_energy_kwh"), r.get("bill"), r.get("occupied_discomfort_kh_learned"),
                    r.get("occupied_discomfort_kh_own"))]  # fmt: skip
        folders = [base / r.building / m for m in MEASURES]
        folders += [base / recipe / r.building for recipe in OTHERS]
        for folder in folders:
            f = ratios(folder)
            if f:
                options.append((f["hvac_energy_kwh"], f.get("bill"), f["occupied_discomfort_kh_learned"],
                                f["occupied_discomfort_kh_own"]))  # fmt: skip
        for hvac, bill, kh, own in options:
            if (not pd.isna(hvac) and hvac < SAVES) or (bill is not None and not pd.isna(bill) and bill < SAVES):
                saves.add(r.building)
                if kh <= own + SAME_KH:
                    holds.add(r.building)
    lower = f"at least {100 * (1 - SAVES):.1f} % lower in HVAC energy or bill"
    played = ", ".join(f"`{recipe}`" for recipe in OTHERS)
    return ["", f"Over the planners (this table's, and where they ran, {played}) and",
            "the measures (the reset; the outdoor air on demand, alone, with the reset or with a margin),",
            f"{len(saves)} of {len(df)} buildings are {lower} with one of them, {len(holds)} at no",
            "more occupied discomfort than their own controls (goal: 12 of 16, all at no more)."]  # fmt: skip


def ruled_lines(study: Study) -> list[str]:
    """A pointer to the planners trained on the reset (`--mpc own_plan=rule`), where their pilots are committed."""
    if not (study.out / "ruled" / "README.md").is_file():
        return []
    return [
        "",
        "The planner trained on the reset as its own plan (`--mpc own_plan=rule`, `--recipe ruled`), where the",
        "starter takes over air loops: [ruled/](ruled/README.md).",
    ]


def _why_not(study: Study) -> str:
    """Why a recipe trained nothing on a building (`study.applies`)."""
    reasons = [*(["no air loop taken over"] if study.recipe in ON_RULE else []),
               *(["no fixed minimum of outdoor air"] if study.recipe in IN_DEMAND else [])]  # fmt: skip
    return " or ".join(reasons)


def _record(out: Path) -> str:
    """This study's README (its record) as the table's folder links it (results/prototypes/, or a recipe's below)."""
    return os.path.relpath(Path(__file__).resolve().parent / "README.md", Path(out).resolve())


# Occupied K.h over the 20 fortnights that count as no more than its own: the small hotel's planner, on its own plan
# at every step, ended 0.0001 K.h above it (its setpoints through float32)
SAME_KH = 0.01
SAVES = 0.995  # a ratio that counts as a saving: 0.5 % lower, not a rounding's 0.003 % (the warehouse on `jump`)


def figure(df: pd.DataFrame, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    done = df.dropna(subset=["hvac_energy_kwh"])
    fig, ax = plt.subplots(figsize=(7, 5))
    x = 100 * (done.hvac_energy_kwh - 1)
    y = done.occupied_discomfort_kh_learned - done.occupied_discomfort_kh_own
    ax.scatter(x, y)
    for xi, yi, label in zip(x, y, done.building, strict=True):
        ax.annotate(label, (xi, yi), fontsize=7, xytext=(3, 3), textcoords="offset points")
    ax.axvline(0, color="grey", lw=0.5)
    ax.axhline(0, color="grey", lw=0.5)
    ax.set_xlabel("HVAC energy vs its own controls (%)")
    ax.set_ylabel("occupied discomfort vs its own controls (K·h, 4 scenarios × 5 weathers)")
    ax.set_title("DOE prototypes: the planner against each building's own controls")
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def table(study: Study, names: list[str] | None = None) -> pd.DataFrame:
    """One row per prototype (or per one of NAMES, as for the buildings scored over several seeds): what was taken
    over, how far the path got, the ratios to its own controls."""
    rows = []
    for model in models():
        name = short_name(model)
        if names and name not in names:
            continue
        status = read_status(study, name)
        row = {"building": name, "model": model.name, "actions": ", ".join(status.get("actions", [])),
               "supply-air loops": status.get("supply_air_loops", ""), "stage": status.get("stage", "not started"),
               "reason": status.get("error") or ""}  # fmt: skip
        if status.get("checked") and not scored(study, name) and not status.get("error"):
            run = study.run_dir(name, 0)
            row["stage"] = "checked, " + ("trained, not scored yet" if finished(run) else "training" if run.exists()
                                          else "not trained yet")  # fmt: skip
        if scored(study, name):
            folder = results_folder(study, name)
            row["stage"] = "scored" if folder.parent == study.out else f"scored (`{FALLBACK}`: {_why_not(study)})"
            row["reason"] = ""
            row |= ratios(folder) or {}
        rows.append(row)
    df = pd.DataFrame(rows)
    study.out.mkdir(parents=True, exist_ok=True)
    for name in df.building:  # each spec as the runs used it, its commented candidates left out
        spec = study.folder(name) / "spec.toml"
        # a scored row of this recipe's own (a fallback's row: its table's spec)
        if spec.is_file() and scored(study, name) and results_folder(study, name).parent == study.out:
            spec = spec_of(study, name)
            (study.out / "specs").mkdir(exist_ok=True)
            kept = [ln for ln in spec.read_text().splitlines() if ln.strip() and not ln.startswith("#")]
            (study.out / "specs" / f"{name}.toml").write_text("\n".join(kept) + "\n")
    df.to_csv(study.out / "prototypes.csv", index=False)
    if "hvac_energy_kwh" in df:
        figure(df, study.out / "savings.png")
    (study.out / "README.md").write_text(markdown(df, study))
    return df
