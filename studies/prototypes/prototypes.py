"""Every DOE reference prototype in the EnergyPlus wheel, taken the way a new user takes a building (issue 52, part 4).

Per building, each stage is the command a user runs (`building init` and the starter's recommended actions, `building
check`, `train --algorithm mpc` with a recipe from recipes.py, `evaluate` on BOPTEST's four scenarios), its output
kept under WORK/<name>/ so the study resumes; `table` writes results/prototypes/. The path and the commands:
README.md beside this file.
"""

from __future__ import annotations

import argparse
import logging
import os
import re
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

from recipes import ON_RULE, PLAYED, RECIPES
from report import table
from study import (
    SCENARIOS,
    Study,
    finished,
    models,
    read_status,
    results_folder,
    rule_spec,
    scored,
    short_name,
    spec_of,
    ventilation_spec,
    write_status,
)

REPO = Path(__file__).resolve().parents[2]
LOG = logging.getLogger("prototypes")
TRAIN_WEATHERS = "CA,CO,FL"
EVAL_WEATHERS = "CA,CO,FL,IL,VA"
TARIFF_LINE = '# tariff = { Electricity = { file = "commercial-tou-demand.toml" } }'

def cli(*args: str) -> list[str]:
    return [sys.executable, "-m", "parallel_eplus.cli", *args]


def recommended(starter: str) -> str:
    """The starter with its recommended actions and the example tariff uncommented (what its notes ask a user)."""
    out, on = [], False
    for line in starter.splitlines():
        heading = line.startswith(("# all ", "# the one thermostat's", "# the one air loop's"))
        kinds = ("thermostats'", "thermostat's", "air loops' supply", "air loop's supply")
        if heading and any(k in line for k in kinds):
            on = True  # a block's heading: its lines follow, to a blank line
        elif on and line.startswith("# "):
            line = line[2:]
        elif not line.strip():
            on = False
        if line.startswith(TARIFF_LINE):
            line = line[2:]
        out.append(line)
    return "\n".join(out) + "\n"


def failure(result: subprocess.CompletedProcess) -> str:
    """The lines of a failed command that say why (its ERROR lines, else its last line)."""
    lines = [ln for ln in (result.stdout + result.stderr).splitlines() if ln.strip()]
    errors = [ln.split(" parallel_eplus: ", 1)[-1] for ln in lines if " ERROR " in ln or ln.startswith("  ")]
    return " ".join(errors[-4:] or lines[-1:])[:600]


def prepare(study: Study, model: Path) -> dict:
    """init, the recommended actions, check: once per building."""
    name = short_name(model)
    folder = study.folder(name)
    folder.mkdir(parents=True, exist_ok=True)
    status = read_status(study, name)
    if "checked" in status:
        return status
    starter, spec = folder / "starter.toml", folder / "spec.toml"
    if not starter.is_file():
        r = subprocess.run(cli("building", "init", str(model), "-o", str(starter), "--name", name),
                           capture_output=True, text=True, cwd=folder)  # fmt: skip
        if r.returncode:
            return write_status(study, name, model=model.name, checked=False, stage="init", error=failure(r))
    text = recommended(starter.read_text())
    spec.write_text(text)
    actions = re.findall(r'^name = "(\w+)"', text.split("[[actions]]", 1)[-1], flags=re.M)
    loops = sum('"System Node Setpoint"' in ln for ln in text.splitlines() if not ln.startswith("#"))
    r = subprocess.run(cli("building", "check", str(spec)), capture_output=True, text=True, cwd=folder)
    (folder / "check.log").write_text(r.stdout + r.stderr)
    fields = {"model": model.name, "actions": actions, "supply_air_loops": loops, "checked": r.returncode == 0}
    if r.returncode:
        fields |= {"stage": "check", "error": failure(r)}
    LOG.info("%s: %s", name, "checked" if r.returncode == 0 else f"check failed: {fields['error']}")
    return write_status(study, name, **fields)


def train(study: Study, name: str, seed: int, deadline: float) -> bool:
    """One run of the recipe until it finishes or the chunk ends (SIGINT: it checkpoints); True when finished."""
    run = study.run_dir(name, seed)
    if finished(run):
        return True
    left = deadline - time.time()
    if left < 120:
        return False
    if list((run / "checkpoints").glob("*.zip")) + list((run / "checkpoints").glob("*.pt")):
        args = ["train", "--quiet", "--resume", str(run), "--timesteps", str(study.steps)]
    else:
        args = ["train", "--quiet", "--building", str(spec_of(study, name)), "--weathers", TRAIN_WEATHERS,
                "--workers", str(study.workers), "--seed", str(seed), "--timesteps", str(study.steps),
                "--run-name", run.name, *RECIPES[study.recipe]]  # fmt: skip
        if run.exists():
            args.append("--overwrite")
    LOG.info("%s seed %d: training (%.0f min left in the chunk)", name, seed, left / 60)
    with open(study.folder(name) / f"train-seed{seed}.log", "a") as log:
        proc = subprocess.Popen(cli(*args), cwd=run.parent.parent, stdout=log, stderr=subprocess.STDOUT)
        try:
            proc.wait(timeout=left)
        except subprocess.TimeoutExpired:
            proc.send_signal(signal.SIGINT)  # the trainer checkpoints and stops its EnergyPlus workers
            proc.wait(timeout=900)
    if finished(run):
        return True
    if proc.returncode not in (0, -signal.SIGINT, 130):
        write_status(study, name, stage="train", error=f"train exited {proc.returncode}: see train-seed{seed}.log")
    return False


def evaluate(study: Study, name: str, deadline: float) -> bool:
    """The finished runs' planners against the building's own controls on BOPTEST's four scenarios."""
    planners = []
    for seed in study.seeds:
        run = study.run_dir(name, seed)
        planner = run / "best" / "planner" if (run / "best" / "planner").is_dir() else run / "planner"
        planners += ["--policy", f"{planner}=Planner"]
    if study.played:
        planners += ["--planner", PLAYED[study.played][1]]
    for scenario in SCENARIOS:
        out = study.folder(name) / (f"eval-{study.played}" if study.played else "eval") / scenario  # apart
        if (study.out / name / f"{scenario}.csv").is_file():
            continue
        if deadline - time.time() < 600:
            return False
        known = sorted(study.folder(name).glob("eval*/*/scenarios.json"))
        if known and not (out / "scenarios.json").is_file():  # each weather's BOPTEST days, found once: reused
            out.mkdir(parents=True, exist_ok=True)
            shutil.copy(known[0], out / "scenarios.json")
        LOG.info("%s: evaluating %s", name, scenario)
        r = subprocess.run(cli("evaluate", "--building", str(spec_of(study, name)), "--baseline",
                               *planners, "--scenario", scenario, "--weathers", EVAL_WEATHERS, "--workers",
                               str(study.workers), "--out", str(out), "--quiet"),
                           capture_output=True, text=True, cwd=study.folder(name))  # fmt: skip
        if r.returncode:
            write_status(study, name, stage=f"evaluate {scenario}", error=failure(r))
            return False
        kept = study.out / name
        kept.mkdir(parents=True, exist_ok=True)  # committed: the next session, maybe another machine, reads it
        shutil.copy(out / "results.csv", kept / f"{scenario}.csv")
    write_status(study, name, evaluated=True, stage="done", error=None)
    return True


def scenarios_of(own: Path) -> dict:
    """Each weather's BOPTEST periods as the building's committed csvs scored them (`scenarios.json`'s form): the
    days a year of its own controls gave, without running the years again."""
    import datetime as dt

    import pandas as pd

    known: dict = {}
    for scenario in SCENARIOS:
        for _, row in pd.read_csv(own / f"{scenario}.csv").drop_duplicates("weather").iterrows():
            first = pd.Timestamp(row.period_start).normalize() - pd.Timedelta(seconds=1)  # the step ending 00:10
            start = (first.normalize() + pd.Timedelta(days=1) - pd.Timedelta(days=int(row.warmup_days))).date()
            start_day = start.timetuple().tm_yday
            known.setdefault(row.weather, {})[scenario] = {
                "scenario": scenario, "day": start_day - 1 + 14, "start_day": start_day,
                "weekday": start.strftime("%A"), "run_days": int(row.run_days), "warmup_days": int(row.warmup_days),
                "first_scored": str(dt.date(2013, 1, 1) + dt.timedelta(days=start_day - 1 + int(row.warmup_days))),
            }  # fmt: skip
    return known


def score_rule(study: Study, name: str, spec: Path, folder: str, deadline: float, own: Path | None = None) -> str:
    """`evaluate --rbc` with the rule `spec` names on the 20 fortnights, its csvs kept in OUT/<name>/<folder>/:
    "done", "chunk" (the chunk ended) or "failed". `own`: a folder of the building's committed csvs whose own
    controls' rows are reused (they are the same runs: EnergyPlus is deterministic) with their days, so only the
    rule runs."""
    import json

    import pandas as pd

    kept = study.out / name / folder
    for scenario in SCENARIOS:
        if (kept / f"{scenario}.csv").is_file():
            continue
        if deadline - time.time() < 300:
            return "chunk"
        out = study.folder(name) / f"eval-{folder}" / scenario
        known = sorted(study.folder(name).glob("eval*/*/scenarios.json"))
        if not (out / "scenarios.json").is_file() and (known or own):  # the BOPTEST days the planner was scored on
            out.mkdir(parents=True, exist_ok=True)
            if known:
                shutil.copy(known[0], out / "scenarios.json")
            else:
                (out / "scenarios.json").write_text(json.dumps(scenarios_of(own), indent=2))
        LOG.info("%s: %s on %s", name, folder, scenario)
        args = ["--building", str(spec), *([] if own else ["--baseline"]), "--rbc", "--scenario", scenario,
                "--weathers", EVAL_WEATHERS, "--workers", str(study.workers), "--out", str(out), "--quiet"]
        r = subprocess.run(cli("evaluate", *args), capture_output=True, text=True, cwd=study.folder(name))
        if r.returncode:
            LOG.warning("%s: %s failed on %s: %s", name, folder, scenario, failure(r))
            return "failed"
        results = pd.read_csv(out / "results.csv")
        if own:
            base = pd.read_csv(own / f"{scenario}.csv")
            results = pd.concat([base[base.controller == "Baseline"], results], ignore_index=True)
        kept.mkdir(parents=True, exist_ok=True)
        results.to_csv(kept / f"{scenario}.csv", index=False)
    return "done"


def rule(study: Study, names: list[str], minutes: float) -> None:
    """Guideline 36's supply-air reset (`evaluate --rbc`: buildings/air_reset.py) against each building's own
    controls on the same 20 fortnights, where the starter takes over air loops: what the air side holds without
    learning. Its spec is the study's with the rule named; the csvs go to OUT/<name>/rule/."""
    deadline = time.time() + 60 * minutes
    for model in sorted(models(), key=lambda m: m.stat().st_size):
        name = short_name(model)
        status = read_status(study, name)
        if (names and name not in names) or not status.get("checked") or not status.get("supply_air_loops"):
            continue
        if score_rule(study, name, rule_spec(study, name), "rule", deadline) == "chunk":
            LOG.info("chunk over: run again to continue")
            return
    LOG.info("every building with air loops done: `table` next")


def ventilation(study: Study, names: list[str], minutes: float) -> None:
    """The building's own controls with the outdoor air on demand (`ventilation = "demand"`, the starter's offer;
    `evaluate --rbc` with buildings/ventilation.py's OnDemand) on the same 20 fortnights, where the model holds a
    fixed minimum of outdoor air; its own controls' rows from the table's csvs. The csvs go to
    OUT/<name>/ventilation/; where the starter takes over supply air, Guideline 36's reset with it to
    OUT/<name>/rule-ventilation/."""
    from parallel_eplus.buildings.idf_text import idf_objects
    from parallel_eplus.buildings.ventilation import plan_ventilation

    deadline = time.time() + 60 * minutes
    for model in sorted(models(), key=lambda m: m.stat().st_size):
        name = short_name(model)
        if (names and name not in names) or not scored(study, name):
            continue
        text = model.read_text(encoding="latin-1")
        if not plan_ventilation(text, idf_objects(text)).added or not prepare(study, model).get("checked"):
            continue
        status = prepare(study, model)
        for folder, reset in (("ventilation", False), ("rule-ventilation", True)):
            if reset and not status.get("supply_air_loops"):
                continue  # the reset with it, where the starter takes over supply air
            spec = ventilation_spec(study, name, reset)
            if score_rule(study, name, spec, folder, deadline, own=results_folder(study, name)) == "chunk":
                LOG.info("chunk over: run again to continue")
                return
    LOG.info("every building with a fixed minimum of outdoor air done: `table` next")


def run(study: Study, names: list[str], minutes: float) -> None:
    """Stages 3-4, building by building (the smallest models first), until the chunk ends."""
    deadline = time.time() + 60 * minutes
    todo = sorted(models(), key=lambda m: m.stat().st_size)
    for model in todo:
        name = short_name(model)
        if names and name not in names:
            continue
        if scored(study, name):
            continue
        status = prepare(study, model)
        if not status.get("checked"):
            continue
        if status.get("stage") == "train" and status.get("error"):
            continue  # failed before: its row says why (delete status.json's error to retry)
        if study.recipe in ON_RULE and not status.get("supply_air_loops"):
            continue  # no air loop taken over: no rule to ride (the table keeps FALLBACK's row)
        if not all(train(study, name, seed, deadline) for seed in study.seeds):
            if time.time() >= deadline - 120:
                LOG.info("chunk over: run again to continue")
                return
            continue
        if not evaluate(study, name, deadline) and time.time() >= deadline - 600:
            LOG.info("chunk over: run again to continue")
            return
    LOG.info("every building done or failed: `table` next")


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("command", choices=["prepare", "run", "rule", "ventilation", "table", "status"])
    p.add_argument("names", nargs="*", help="short names (default: all 16), e.g. medium-office")
    p.add_argument("--work", type=Path, help="the runs and evaluations (default: $WORK, else ../prototypes-RECIPE)")
    p.add_argument("--out", type=Path, default=REPO / "results" / "prototypes")
    p.add_argument("--steps", type=int, default=Study.steps)
    p.add_argument("--seeds", default="0", help="comma-separated")
    p.add_argument("--minutes", type=float, default=110.0, help="the chunk: stop (checkpointed) after this long")
    p.add_argument("--recipe", choices=sorted(RECIPES) + sorted(PLAYED), default="banded",
                   help="the recipe: trained (RECIPES), or a trained one's planners played otherwise (PLAYED)")
    a = p.parse_args(argv)
    trained, played = (PLAYED[a.recipe][0], a.recipe) if a.recipe in PLAYED else (a.recipe, "")
    a.work = a.work or Path(os.environ.get("WORK", REPO.parent / f"prototypes-{trained}"))
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(message)s")
    fallback = REPO / "results" / "prototypes" if trained in ON_RULE else None  # FALLBACK's table: the default --out
    study = Study(a.work, a.out, a.steps, seeds=tuple(int(s) for s in a.seeds.split(",")), recipe=trained,
                  played=played, fallback=fallback)  # fmt: skip
    if a.command == "prepare":
        for model in models():
            if not a.names or short_name(model) in a.names:
                prepare(study, model)
    elif a.command == "run":
        run(study, a.names, a.minutes)
    elif a.command == "rule":
        rule(study, a.names, a.minutes)
    elif a.command == "ventilation":
        ventilation(study, a.names, a.minutes)
    elif a.command == "table":
        print(table(study).to_string())
    else:
        for model in models():
            s = read_status(study, short_name(model))
            print(short_name(model), s.get("stage", "checked" if s.get("checked") else "not prepared"),
                  s.get("error") or "")  # fmt: skip
    return 0


if __name__ == "__main__":
    sys.exit(main())
