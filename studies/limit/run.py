"""The ceiling, building by building (issue 89): the oracle beside the own controls, the rule and the learned planner.

Each cell is one building, one of BOPTEST's test periods, one weather and one objective, run as the user runs it:

    parallel-eplus evaluate --building B --scenario S --weathers W --baseline [--rbc] [--policy PLANNER] \
        --oracle SETTINGS --workers 2 --out WORK/B/S/OBJECTIVE --resume

Cells run in the plan's order, one at a time (the oracle uses both cores), in chunks: `run --hours H` starts no cell
after H hours and interrupts one still running an hour past them (evaluate stops cleanly; `--resume` keeps the
episodes it finished). Re-running `run` continues where the last chunk stopped: a cell whose results.csv has every
controller is done. Every start, end and failure goes to results/limit/progress.log; `table` writes
results/limit/table.md and limit.json from every finished cell (`run` does after each cell).

    .venv/bin/python studies/limit/run.py run --hours 1.9                      # the next chunk of the plan
    .venv/bin/python studies/limit/run.py run --only datacenter-2zone --hours 1  # one building's cells
    .venv/bin/python studies/limit/run.py status                               # done, running, left
    .venv/bin/python studies/limit/run.py table

More buildings: `run --add NAME=SPEC` (a DOE prototype's spec written by `studies/prototypes/prototypes.py prepare`),
kept in WORK/buildings.json; their cells follow the built-in buildings' in each period.

The learned planner's column needs a trained planner per building: `--planner BUILDING=runs/NAME/planner` (given to
`run`, kept in WORK/planners.json); a cell without one is run without it and its planner column stays empty. The
episodes stay in WORK (default ../limit-work beside the repository): only the tables are committed.
"""

from __future__ import annotations

import argparse
import csv
import datetime as dt
import json
import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
OUT = ROOT / "results" / "limit"
WORK = ROOT.parent / "limit-work"
ORACLE = "horizon_h=24,interval_min=60,candidates=24"  # the oracle's settings for every cell (its defaults)
SCENARIOS = ("typical_cool", "peak_cool", "typical_heat", "peak_heat")
# (building, rule?) in the order they run: the paper's data center and the small office first (issue 89's first chunk)
BUILDINGS = (("datacenter-2zone", True), ("office-small", False), ("datacenter-crac", False), ("office-medium", True))
WEATHERS = ("CA", "IL")  # a training weather and a held-out one
# energy: the spec's own objective (its energy terms; the medium office's HVAC energy); cost-SCENARIO: a copy of the
# spec with the cost objective (each HVAC fuel's energy at its price when the step began) under BOPTEST's constant or
# dynamic electricity prices (parallel_eplus/buildings/tariffs/boptest-*.toml). BOPTEST's highly dynamic scenario
# ships no prices here.
OBJECTIVES = ("energy", "cost-constant", "cost-dynamic")
LABELS = {"Baseline": "own", "Rule-based": "rule", "Oracle": "oracle"}
FIGURES = ("energy_kwh", "hvac_energy_kwh", "cost", "discomfort_kh", "in_band_pct")


def added(work: Path = WORK) -> dict[str, dict]:
    """Buildings added with `run --add NAME=SPEC` (a DOE prototype's spec): name -> spec, rule?"""
    path = work / "buildings.json"
    return json.loads(path.read_text()) if path.is_file() else {}


def plan(work: Path = WORK) -> list[dict]:
    """Every cell, in order: the energy objective's (the first weather's typical cooling fortnight of each building
    first), then the cost objectives'."""
    buildings = [(b, rule, b) for b, rule in BUILDINGS] + [(b, a["rule"], a["spec"]) for b, a in added(work).items()]
    cells = []
    for objective in OBJECTIVES:
        for weather in WEATHERS:
            for scenario in SCENARIOS:
                for building, rule, spec in buildings:
                    cells.append({"building": building, "rule": rule, "scenario": scenario, "weather": weather,
                                  "objective": objective, "spec": spec})  # fmt: skip
    return cells


def spec_for(work: Path, c: dict) -> str:
    """The spec a cell runs: the built-in one (energy), or a copy of it under the cost objective and a price
    scenario's tariff, written into WORK/specs."""
    from parallel_eplus.buildings.building import load_building

    if c["objective"] == "energy":
        return c["spec"]
    prices = c["objective"].removeprefix("cost-")
    own = load_building(c["spec"]).spec  # its models as found from its spec, by absolute path below
    text = own.path.read_text()
    head = f"# Written by studies/limit/run.py: {c['building']} under the cost objective, BOPTEST's {prices} prices.\n"
    text = re.sub(r'^name = "[^"]*"', f'name = "{c["building"]}-{c["objective"]}"', text, count=1, flags=re.M)
    text, n = re.subn(r'^objective = "[^"]*"', 'objective = "cost"', text, count=1, flags=re.M)
    if not n:
        text, n = re.subn(r"^\[reward\]\n", '[reward]\nobjective = "cost"\n', text, count=1, flags=re.M)
    tariff = f'tariff = {{ Electricity = {{ file = "boptest-{prices}.toml" }} }}\n'
    text, m = re.subn(r"^tariff = .*\n", tariff, text, count=1, flags=re.M)
    if not m:
        text, m = re.subn(r"^\[kpis\]\n", "[kpis]\n" + tariff, text, count=1, flags=re.M)
    if not (n and m):
        raise SystemExit(f"{c['building']}'s spec has no [reward] or [kpis] table to set the cost objective in")
    for key, model in (("idf", own.idf), ("baseline_idf", own.baseline_idf)):
        if model is not None:
            text = re.sub(rf'^{key} = "[^"]*"', f'{key} = "{model}"', text, count=1, flags=re.M)
    path = work / "specs" / f"{c['building']}-{c['objective']}.toml"
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(head + text)
    return str(path)


def cell_dir(work: Path, c: dict) -> Path:
    return work / c["building"] / c["scenario"] / c["weather"] / c["objective"]


def planners(work: Path) -> dict[str, str]:
    path = work / "planners.json"
    return json.loads(path.read_text()) if path.is_file() else {}


def expected(c: dict, planner: str | None) -> set[str]:
    labels = {"Baseline", "Oracle"} | ({"Rule-based"} if c["rule"] else set())
    return labels | ({"planner"} if planner else set())


def finished(work: Path, c: dict) -> list[dict]:
    path = cell_dir(work, c) / "results.csv"
    if not path.is_file():
        return []
    with path.open() as f:
        return list(csv.DictReader(f))


def done(work: Path, c: dict) -> bool:
    rows = finished(work, c)
    labels = {("planner" if r["controller"].startswith("MPC") else r["controller"]) for r in rows}
    return expected(c, planners(work).get(c["building"])) <= labels


def log(text: str) -> None:
    OUT.mkdir(parents=True, exist_ok=True)
    line = f"{dt.datetime.now(dt.UTC):%Y-%m-%d %H:%M:%S}Z {text}"
    print(line, flush=True)
    with (OUT / "progress.log").open("a") as f:
        f.write(line + "\n")


def command(work: Path, c: dict) -> list[str]:
    cmd = [str(ROOT / ".venv" / "bin" / "parallel-eplus"), "evaluate", "--building", spec_for(work, c), "--scenario",
           c["scenario"], "--weathers", c["weather"], "--baseline", "--oracle", ORACLE, "--workers", "2", "--out",
           str(cell_dir(work, c)), "--resume", "--quiet"]  # fmt: skip
    if c["rule"]:
        cmd.append("--rbc")
    planner = planners(work).get(c["building"])
    if planner:
        cmd += ["--policy", planner]
    return cmd


def run(args: argparse.Namespace) -> int:
    work = args.work
    work.mkdir(parents=True, exist_ok=True)
    if args.add:
        from parallel_eplus.buildings.building import load_building

        known = added(work)
        for item in args.add:
            name, _, spec = item.partition("=")
            b = load_building(spec)  # a spec that does not load fails here
            known[name] = {"spec": str(Path(spec).resolve()), "rule": bool(b.spec.controller)}
        (work / "buildings.json").write_text(json.dumps(known, indent=1))
    if args.planner:
        known = planners(work)
        for item in args.planner:
            building, _, path = item.partition("=")
            known[building] = str(Path(path).resolve())
        (work / "planners.json").write_text(json.dumps(known, indent=1))
    start, budget = time.monotonic(), args.hours * 3600
    cells = [c for c in plan(work) if not args.only or c["building"] in args.only.split(",")]
    for c in cells:
        if done(work, c):
            continue
        if time.monotonic() - start > budget:
            log(f"chunk over ({args.hours} h): the next cells wait for the next `run`")
            break
        name = f"{c['building']} {c['scenario']} {c['weather']} {c['objective']}"
        log(f"start {name}")
        cell_dir(work, c).mkdir(parents=True, exist_ok=True)
        t0 = time.monotonic()
        with (cell_dir(work, c) / "evaluate.log").open("a") as out:
            proc = subprocess.Popen(command(work, c), cwd=ROOT, stdout=out, stderr=subprocess.STDOUT)
            try:
                deadline = start + budget + 3600
                while proc.poll() is None:
                    if time.monotonic() > deadline:
                        log(f"interrupting {name}: an hour past the chunk's budget (its finished episodes are kept)")
                        proc.send_signal(signal.SIGINT)
                        proc.wait(120)
                        break
                    time.sleep(5)
            except BaseException:
                proc.send_signal(signal.SIGINT)
                proc.wait(120)
                raise
        minutes = (time.monotonic() - t0) / 60
        state = "done" if done(work, c) else f"not finished (exit {proc.returncode}; see its evaluate.log)"
        log(f"{state} {name} in {minutes:.1f} min")
        table(args)
    return 0


def oracle_stats(rows: list[dict]) -> dict:
    for r in rows:
        if r["controller"] == "Oracle":
            path = Path(r["episode_dir"]) / "oracle.json"
            if path.is_file():
                s = json.loads(path.read_text())
                return {"decisions": s["decisions"], "s_per_decision": round(s["ms_per_decision_mean"] / 1000, 2),
                        "candidates_per_decision": s["candidates_per_decision_mean"]}  # fmt: skip
    return {}


def table(args: argparse.Namespace) -> int:
    work, entries = args.work, []
    for c in plan(work):
        rows = finished(work, c)
        if not rows:
            continue
        by = {("planner" if r["controller"].startswith("MPC") else LABELS.get(r["controller"], r["controller"])): r
              for r in rows}  # fmt: skip
        entry = {k: c[k] for k in ("building", "scenario", "weather", "objective")} | {"complete": done(work, c)}
        entry["controllers"] = {k: {f: _number(r.get(f)) for f in FIGURES} for k, r in by.items()}
        entry["oracle"] = oracle_stats(rows)
        entries.append(entry)
    OUT.mkdir(parents=True, exist_ok=True)
    (OUT / "limit.json").write_text(json.dumps({"oracle_settings": ORACLE, "cells": entries}, indent=1) + "\n")
    lines = ["| building | period | weather | objective | controller | energy (kWh) | × own | HVAC (kWh) | × own | "
             "cost ($) | discomfort (K·h/zone) | in band | oracle s/decision |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|---|"]  # fmt: skip
    for e in entries:
        own = e["controllers"].get("own", {})
        for k in ("own", "rule", "planner", "oracle"):
            v = e["controllers"].get(k)
            if v is None:
                continue
            ratio = lambda f, v=v, own=own: _ratio(v.get(f), own.get(f))  # noqa: E731
            speed = e["oracle"].get("s_per_decision", "") if k == "oracle" else ""
            lines.append(f"| {e['building']} | {e['scenario']} | {e['weather']} | {e['objective']} | {k} | "
                         f"{_fmt(v['energy_kwh'], 0)} | {ratio('energy_kwh')} | {_fmt(v['hvac_energy_kwh'], 0)} | "
                         f"{ratio('hvac_energy_kwh')} | {_fmt(v['cost'], 2)} | {_fmt(v['discomfort_kh'], 2)} | "
                         f"{_fmt(v['in_band_pct'], 2)} % | {speed} |")  # fmt: skip
    (OUT / "table.md").write_text("\n".join(lines) + "\n")
    return 0


def status(args: argparse.Namespace) -> int:
    cells = plan(args.work)
    finished_cells = [c for c in cells if done(args.work, c)]
    print(f"{len(finished_cells)} of {len(cells)} cells done (work: {args.work})")
    for c in cells:
        mark = "done" if done(args.work, c) else ("started" if cell_dir(args.work, c).is_dir() else "left")
        print(f"  {mark:8} {c['building']} {c['scenario']} {c['weather']} {c['objective']}")
    return 0


def _number(text):
    try:
        return float(text)
    except (TypeError, ValueError):
        return None


def _fmt(v, digits: int) -> str:
    return "–" if v is None else f"{v:,.{digits}f}"


def _ratio(v, own) -> str:
    return "–" if v is None or not own else f"{v / own:.3f}"


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("stage", choices=("run", "table", "status"))
    p.add_argument("--hours", type=float, default=1.9, help="start no cell after this many hours (default 1.9)")
    p.add_argument("--only", help="these buildings' cells only (comma-separated)")
    p.add_argument("--planner", action="append", metavar="BUILDING=PATH", help="a trained planner for the column")
    p.add_argument("--add", action="append", metavar="NAME=SPEC", help="one more building (its spec file), kept")
    p.add_argument("--work", type=Path, default=WORK, help=f"where the episodes go (default {WORK})")
    args = p.parse_args()
    os.environ.setdefault("PYTHONUNBUFFERED", "1")
    return {"run": run, "table": table, "status": status}[args.stage](args)


if __name__ == "__main__":
    sys.exit(main())
