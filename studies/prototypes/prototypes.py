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
import signal
import subprocess
import sys
import time
from pathlib import Path

from commands import LOG, cli, own_rows, prepare, score
from measures import rule, ventilation
from recipes import FALLBACK, IN_DEMAND, ON_RULE, PLAYED, RECIPES
from report import table
from study import Study, applies, claimed, finished, models, read_status, scored, short_name, spec_of, write_status

REPO = Path(__file__).resolve().parents[2]
TRAIN_WEATHERS = "CA,CO,FL"


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
    """The finished runs' planners against the building's own controls on BOPTEST's four scenarios (their rows reused
    from the fallback's table where it has them)."""
    planners = []
    for seed in study.seeds:
        run = study.run_dir(name, seed)
        planner = run / "best" / "planner" if (run / "best" / "planner").is_dir() else run / "planner"
        planners += ["--policy", f"{planner}=Planner"]
    if study.played:
        planners += ["--planner", PLAYED[study.played][1]]
    own = own_rows(study.fallback / name) if study.fallback else None
    runs = f"eval-{study.played}" if study.played else "eval"  # a played recipe's evaluations apart
    state, why = score(study, name, spec_of(study, name), runs, study.out / name, planners, deadline, own, need=600)
    if state == "failed":
        write_status(study, name, stage="evaluate", error=why)
    if state != "done":
        return False
    write_status(study, name, evaluated=True, stage="done", error=None)
    return True


def run_one(study: Study, model: Path, deadline: float) -> bool:
    """One building's stages 3-4 as far as the chunk goes; False when the chunk is over."""
    name = short_name(model)
    status = prepare(study, model)
    if not status.get("checked"):
        return True
    if status.get("stage") == "train" and status.get("error"):
        return True  # failed before: its row says why (delete status.json's error to retry)
    if not applies(study, name):
        return True  # no reset to ride, no outdoor air to put on demand: the table keeps FALLBACK's row
    if not all(train(study, name, seed, deadline) for seed in study.seeds):
        return time.time() < deadline - 120
    return evaluate(study, name, deadline) or time.time() < deadline - 600


def run(study: Study, names: list[str], minutes: float) -> None:
    """Stages 3-4, building by building (the smallest models first), until the chunk ends."""
    deadline = time.time() + 60 * minutes
    todo = sorted(models(), key=lambda m: m.stat().st_size)
    others: list[str] = []  # the buildings another `run` has
    for model in todo:
        name = short_name(model)
        if names and name not in names or scored(study, name):
            continue
        with claimed(study, name) as mine:
            if not mine:
                LOG.info("%s: another `run` has it, skipped", name)
                others.append(name)
                continue
            if not run_one(study, model, deadline):
                LOG.info("chunk over: run again to continue")
                return
    if others:
        LOG.info("every building done or failed but %s, another `run`'s: `table` when it ends", ", ".join(others))
    else:
        LOG.info("every building done or failed: `table` next")


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("command", choices=["prepare", "run", "rule", "ventilation", "table", "status"])
    p.add_argument("names", nargs="*", help="short names (default: all 16), e.g. medium-office; `table`: its rows")
    p.add_argument("--work", type=Path, help="the runs and evaluations (default: $WORK, else ../prototypes-RECIPE)")
    p.add_argument("--out", type=Path, help=f"the table (default: results/prototypes/, RECIPE/ in it but {FALLBACK})")
    p.add_argument("--steps", type=int, default=Study.steps)
    p.add_argument("--seeds", default="0", help="comma-separated")
    p.add_argument("--minutes", type=float, default=110.0, help="the chunk: stop (checkpointed) after this long")
    p.add_argument(
        "--recipe",
        choices=sorted(RECIPES) + sorted(PLAYED),
        default="banded",
        help="the recipe: trained (RECIPES), or a trained one's planners played otherwise (PLAYED)",
    )
    a = p.parse_args(argv)
    trained, played = (PLAYED[a.recipe][0], a.recipe) if a.recipe in PLAYED else (a.recipe, "")
    results = REPO / "results" / "prototypes"
    a.out = a.out or (results if a.recipe == FALLBACK else results / a.recipe)
    a.work = a.work or Path(os.environ.get("WORK", REPO.parent / f"prototypes-{trained}"))
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(message)s")
    # FALLBACK's table: its rows where the recipe does not apply, and its own controls' rows everywhere
    fallback = results if trained in ON_RULE | IN_DEMAND or played not in ("", FALLBACK) else None
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
        print(table(study, a.names).to_string())
    else:
        for model in models():
            s = read_status(study, short_name(model))
            print(short_name(model), s.get("stage", "checked" if s.get("checked") else "not prepared"),
                  s.get("error") or "")  # fmt: skip
    return 0


if __name__ == "__main__":
    sys.exit(main())
