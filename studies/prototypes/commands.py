"""The commands a user runs on a building, as the prototypes study scripts them: `building init` with the starter's
recommended actions, `building check`, and `evaluate` on BOPTEST's four scenarios, each run's output kept so the study
resumes."""

from __future__ import annotations

import json
import logging
import re
import shutil
import subprocess
import sys
import time
from pathlib import Path

from study import SCENARIOS, Study, read_status, short_name, write_status

from parallel_eplus.optimize.prepare import recommended  # the starter's recommended actions, as optimize takes them

LOG = logging.getLogger("prototypes")
EVAL_WEATHERS = "CA,CO,FL,IL,VA"


def cli(*args: str) -> list[str]:
    return [sys.executable, "-m", "parallel_eplus.cli", *args]


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


def score(
    study: Study,
    name: str,
    spec: Path,
    runs: str,
    kept: Path,
    controllers: list[str],
    deadline: float,
    own: Path | None = None,
    need: float = 300.0,
) -> tuple[str, str]:
    """`evaluate` of `controllers` (`--rbc`, or planners) in `spec` on the 20 fortnights, each scenario's csv kept in
    `kept` (committed: the next session, maybe another machine, reads it) and its runs in WORK/<name>/<runs>/:
    ("done" | "chunk" | "failed", why). A scenario starts only with `need` seconds left in the chunk. `own`: a
    folder of the building's committed csvs whose own controls' rows are reused (the same runs: EnergyPlus is
    deterministic) with their days, so only `controllers` run; else `--baseline` runs them too."""
    import pandas as pd

    for scenario in SCENARIOS:
        if (kept / f"{scenario}.csv").is_file():
            continue
        if deadline - time.time() < need:
            return "chunk", ""
        out = study.folder(name) / runs / scenario
        known = sorted(study.folder(name).glob("eval*/*/scenarios.json"))
        if not (out / "scenarios.json").is_file() and (known or own):  # each weather's BOPTEST days, found once
            out.mkdir(parents=True, exist_ok=True)
            if known:
                shutil.copy(known[0], out / "scenarios.json")
            else:
                (out / "scenarios.json").write_text(json.dumps(scenarios_of(own), indent=2))
        LOG.info("%s: %s on %s", name, runs, scenario)
        args = [
            "--building",
            str(spec),
            *([] if own else ["--baseline"]),
            *controllers,
            "--scenario",
            scenario,
            "--weathers",
            EVAL_WEATHERS,
            "--workers",
            str(study.workers),
            "--out",
            str(out),
            "--quiet",
        ]
        r = subprocess.run(cli("evaluate", *args), capture_output=True, text=True, cwd=study.folder(name))
        if r.returncode:
            LOG.warning("%s: %s failed on %s: %s", name, runs, scenario, failure(r))
            return "failed", failure(r)
        results = pd.read_csv(out / "results.csv")
        if own:
            base = pd.read_csv(own / f"{scenario}.csv")
            results = pd.concat([base[base.controller == "Baseline"], results], ignore_index=True)
        kept.mkdir(parents=True, exist_ok=True)
        results.to_csv(kept / f"{scenario}.csv", index=False)
    return "done", ""


def own_rows(folder: Path) -> Path | None:
    """`folder` where it holds a csv of every scenario (the building's own controls' rows to reuse), else None."""
    return folder if all((folder / f"{s}.csv").is_file() for s in SCENARIOS) else None
