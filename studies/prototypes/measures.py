"""The measures a building takes without learning, scored as the planner is (`prototypes.py rule`, `prototypes.py
ventilation`): Guideline 36's supply-air reset where the starter takes over air loops, and the outdoor air on demand
where the model holds a fixed minimum; each `evaluate --rbc` on the same 20 fortnights, its csvs in
OUT/<name>/<measure>/ beside the planner's."""

from __future__ import annotations

import time

from commands import LOG, own_rows, prepare, score
from study import (
    DEMAND_RULES,
    Study,
    demand_controllers,
    demand_spec,
    models,
    own_schedules,
    read_status,
    results_folder,
    rule_spec,
    short_name,
)


def rule(study: Study, names: list[str], minutes: float) -> None:
    """Guideline 36's supply-air reset (buildings/rules/air_reset.py) against each building's own controls, where the
    starter takes over air loops: what the air side holds without learning. Its spec is the study's with the rule
    named; the csvs go to OUT/<name>/rule/."""
    deadline = time.time() + 60 * minutes
    for model in sorted(models(), key=lambda m: m.stat().st_size):
        name = short_name(model)
        status = read_status(study, name)
        if (names and name not in names) or not status.get("checked") or not status.get("supply_air_loops"):
            continue
        kept = study.out / name / "rule"
        if score(study, name, rule_spec(study, name), "eval-rule", kept, ["--rbc"], deadline)[0] == "chunk":
            LOG.info("chunk over: run again to continue")
            return
    LOG.info("every building with air loops done: `table` next")


def ventilation(study: Study, names: list[str], minutes: float) -> None:
    """The building's own controls with the outdoor air on demand (`ventilation = "demand"`, the starter's offer;
    rules/on_demand.py's OnDemand), where the model holds a fixed minimum of outdoor air; its own controls' rows
    from the table's csvs. The csvs go to OUT/<name>/ventilation/; where the starter takes over supply air,
    Guideline 36's reset with it to OUT/<name>/rule-ventilation/; where every action has a schedule of the building's
    own, each thermostat 0.02 K inside it (buildings/rules/own_margin.py) to OUT/<name>/margin-ventilation/."""
    deadline = time.time() + 60 * minutes
    for model in sorted(models(), key=lambda m: m.stat().st_size):
        name = short_name(model)
        own = own_rows(results_folder(study, name))
        if (names and name not in names) or not own or not prepare(study, model).get("checked"):
            continue
        if not demand_controllers(study, name):
            continue
        for folder in DEMAND_RULES:
            if folder == "rule-ventilation" and not read_status(study, name).get("supply_air_loops"):
                continue  # the reset with it, where the starter takes over supply air
            spec, kept = demand_spec(study, name, folder), study.out / name / folder
            if folder == "margin-ventilation" and not own_schedules(spec):
                continue  # a margin inside each own schedule, where every action has one
            if score(study, name, spec, f"eval-{folder}", kept, ["--rbc"], deadline, own=own)[0] == "chunk":
                LOG.info("chunk over: run again to continue")
                return
    LOG.info("every building with a fixed minimum of outdoor air done: `table` next")
