"""A year through exported controllers: parity with the in-process policy, and closed loop over HTTP.

For each case (a committed policy and its building) it exports the policy, serves it (`parallel-eplus serve`, one
process each), and runs a year in EnergyPlus twice, `evaluate --policy` in process and `--controller-url` through
the server. It writes:
- results/deploy/parity.md: the exported graph replayed on the in-process year's recorded observations, the
  largest difference from the setpoints the policy gave (physical units; the requirement is 1e-5);
- results/deploy/closed_loop.md: the two runs' tables and step tables compared, and what a year costs over HTTP
  against in process (the two episodes' wall times, run side by side).

    .venv/bin/python studies/deploy/deploy_year.py [--days 365] [--cases 0,1,2,3,4] [--weather CA]

Each case's figures are kept in results/deploy/year.json; a run replaces the cases it ran and the tables show all.
"""

from __future__ import annotations

import argparse
import datetime as dt
import json
import logging
import os
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import pandas as pd

from parallel_eplus.deploy.export.parity import replay
from parallel_eplus.deploy.export.policy import export
from parallel_eplus.evaluation.controllers import http_controller, policy_controller
from parallel_eplus.evaluation.sweep import run_sweep

ROOT = Path(__file__).resolve().parents[2]
CASES = [  # (name, committed policy, building: None for the data center); --cases picks by index
    ("TRPO, data center (time features)", "results/paper/models/paper-ca-co-fl-time", None),
    ("PPO, data center (time features)", "results/paper/models/ppo-ca-co-fl-time", None),
    ("SAC, data center", "results/compare/runs/sac", None),
    (
        "TRPO, CRAC data center (learned)",
        "results/learned/datacenter-crac/runs/datacenter-crac-seed0",
        "datacenter-crac",
    ),
    ("TRPO, small office (learned)", "results/learned/office-small/runs/office-small-seed0", "office-small"),
]
FIGURES = ["power_kw", "in_band_pct", "energy_mwh", "peak_kw", "discomfort_kh"]
log = logging.getLogger("deploy_year")


def serve(directory: Path, logs: Path) -> tuple[str, subprocess.Popen]:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    out = (logs / f"{directory.name}.log").open("w")
    cli = [sys.executable, "-m", "parallel_eplus.cli", "serve", str(directory), "--port", str(port)]
    proc = subprocess.Popen(cli, stdout=out, stderr=subprocess.STDOUT)
    url = f"http://127.0.0.1:{port}"
    for _ in range(300):
        try:
            socket.create_connection(("127.0.0.1", port), timeout=1).close()
            return url, proc
        except OSError:
            time.sleep(0.2)
    proc.kill()
    raise SystemExit(f"{directory}: the server did not start")


def wall_s(episode_dir: Path) -> float:
    """An episode's wall time: from its model file (written at launch) to its step table (written at its end)."""
    return (episode_dir / "steps.parquet").stat().st_mtime - (episode_dir / "model.idf").stat().st_mtime


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--days", type=int, default=365, help="each episode's period (default a year)")
    parser.add_argument("--cases", default=",".join(str(i) for i in range(len(CASES))), help="indices into CASES")
    parser.add_argument("--weather", default="CA")
    parser.add_argument("--out", type=Path, default=ROOT / "results" / "deploy")
    args = parser.parse_args()
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(message)s")
    from parallel_eplus.errors import Interrupts

    store = args.out / "year.json"  # every case measured so far; a run updates the rows of the cases it ran
    rows = json.loads(store.read_text()) if store.is_file() else {}
    with tempfile.TemporaryDirectory(prefix="deploy-year-") as tmp_text, Interrupts():
        tmp = Path(tmp_text)
        for i in [int(k) for k in args.cases.split(",")]:
            name, model, building = CASES[i]
            days = args.days
            controller_dir = tmp / f"controller-{i}"
            export(ROOT / model, controller_dir)
            url, proc = serve(controller_dir, tmp)
            try:
                log.info("%s: %d days in process and over HTTP, side by side", name, days)
                policy, remote = policy_controller(str(ROOT / model)), http_controller(url)
                df = run_sweep([policy, remote], [args.weather], days, 2, tmp / f"eval-{i}", progress=False,
                               building=building)  # fmt: skip
            finally:
                proc.terminate()
                proc.wait(timeout=30)
            dirs = [Path(d) for d in df.episode_dir]
            local, http = (pd.read_parquet(d / "steps.parquet") for d in dirs)
            result = replay(controller_dir, local)
            numeric = local.select_dtypes("number").columns
            step_diff = float((local[numeric] - http[numeric]).abs().max().max())
            figures = [f for f in FIGURES if f in df]
            same = bool(np.array_equal(*(df[figures].iloc[k].to_numpy(float) for k in (0, 1)), equal_nan=True))
            walls = [wall_s(d) for d in dirs]
            rows[name] = {
                "index": i, "model": model, "days": days, "parity": result, "steps": len(local),
                "identical": bool(local.equals(http)), "step_diff": step_diff, "same_row": same,
                "figures": df[figures].iloc[0].to_dict(), "walls": walls,
                "when": f"{dt.datetime.now():%Y-%m-%d %H:%M}, load average {os.getloadavg()[0]:.1f}",
            }  # fmt: skip
            log.info("%s: identical %s, in process %.0f s, over HTTP %.0f s", name, local.equals(http), *walls)
            args.out.mkdir(parents=True, exist_ok=True)
            store.write_text(json.dumps(rows, indent=1))
            write(args, rows)  # after each case: a stopped run keeps what it measured


def write(args, store: dict) -> None:
    cases = sorted(store.values(), key=lambda r: r["index"])
    when = "; ".join(f"{CASES[r['index']][0]}: {r['when']}" for r in cases)
    head = (
        f"`python studies/deploy/deploy_year.py --weather {args.weather}` on {os.cpu_count()} cores shared with other "
        f"sessions (when: {when})."
    )
    rows = []
    for c in cases:
        r = c["parity"]
        worst = max(r["max_abs_diff"].values())
        each = ", ".join(f"{k} {v:.1e}" for k, v in r["max_abs_diff"].items())
        rows.append(f"| {CASES[c['index']][0]} | `{c['model']}` | {c['days']} | {r['steps']} | {worst:.1e} | {each} |")
    (args.out / "parity.md").write_text("\n".join([
        "# Export parity over a year",
        "",
        head + " Each policy's episode in process (`evaluate --policy`), then its exported `controller.onnx` in "
        "onnxruntime on every recorded observation: the largest difference from the setpoint the policy gave "
        "(physical units: °C, kg/s). The requirement is 1e-5.",
        "",
        "| policy | model | days | steps compared | largest difference | per setpoint |",
        "| --- | --- | --- | --- | --- | --- |",
        *rows, "",
    ]))  # fmt: skip
    rows = [
        f"| {CASES[c['index']][0]} | {c['days']} | {c['steps']} | {'yes' if c['identical'] else 'no'} | "
        f"{c['step_diff']:.1e} | {'yes' if c['same_row'] else 'no'} | {c['figures'].get('power_kw', float('nan')):.2f}"
        f" | {c['figures'].get('in_band_pct', float('nan')):.2f} | {c['walls'][0]:.0f} | {c['walls'][1]:.0f} | "
        f"{c['walls'][1] / c['walls'][0]:.2f} |"
        for c in cases
    ]
    (args.out / "closed_loop.md").write_text("\n".join([
        "# Closed loop through the controller server",
        "",
        head + " Each policy's episode twice in EnergyPlus, side by side on the 2 cores: in process "
        "(`evaluate --policy`) and through `parallel-eplus serve` (`evaluate --controller-url`: every step's "
        "readings over HTTP, the setpoints back). Wall times from each episode's launch to its step table; the two "
        "share the machine (and it was shared with other sessions), so their ratio is the figure to read.",
        "",
        "| policy | days | steps | step tables identical | largest step difference | same table row | power (kW) "
        "| in band (%) | in process (s) | over HTTP (s) | ratio |",
        "| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |",
        *rows, "",
    ]))  # fmt: skip


if __name__ == "__main__":
    main()
