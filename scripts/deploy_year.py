"""A year through exported controllers: parity with the in-process policy, and closed loop over HTTP.

For each case (a committed policy and its building) it exports the policy, serves it (`parallel-eplus serve`, one
process each), and runs a year in EnergyPlus twice, `evaluate --policy` in process and `--controller-url` through
the server. It writes:
- results/deploy/parity.md: the exported graph replayed on the in-process year's recorded observations, the
  largest difference from the setpoints the policy gave (physical units; the requirement is 1e-5);
- results/deploy/closed_loop.md: the two years' tables and step tables compared, and what a year costs over HTTP
  against in process (TRPO on the data center, each alone on one worker, run in turn A B B A).

    .venv/bin/python scripts/deploy_year.py [--days 365] [--weather CA]
"""

from __future__ import annotations

import argparse
import datetime as dt
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

from parallel_eplus.deploy.export import export
from parallel_eplus.deploy.parity import replay
from parallel_eplus.evaluation.controllers import http_controller, policy_controller
from parallel_eplus.evaluation.sweep import run_sweep

ROOT = Path(__file__).resolve().parents[1]
CASES = [  # (name, committed policy, building: None for the data center)
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


def timed(controller, weather: str, days: int, out: Path, building: str | None) -> float:
    t0 = time.perf_counter()
    run_sweep([controller], [weather], days, 1, out, progress=False, building=building)
    return time.perf_counter() - t0


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--days", type=int, default=365)
    parser.add_argument("--weather", default="CA")
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--out", type=Path, default=ROOT / "results" / "deploy")
    args = parser.parse_args()
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(message)s")
    parity, loop, servers = [], [], []
    with tempfile.TemporaryDirectory(prefix="deploy-year-") as tmp_text:
        tmp = Path(tmp_text)
        try:
            for i, (name, model, building) in enumerate(CASES):
                controller_dir = tmp / f"controller-{i}"
                export(ROOT / model, controller_dir)
                url, proc = serve(controller_dir, tmp)
                servers.append(proc)
                log.info("%s: a year in process and over HTTP", name)
                t0 = time.perf_counter()
                policy, remote = policy_controller(str(ROOT / model)), http_controller(url)
                df = run_sweep([policy, remote], [args.weather], args.days, args.workers, tmp / f"eval-{i}",
                               progress=False, building=building)  # fmt: skip
                log.info("%s: %.0f s", name, time.perf_counter() - t0)
                local, http = (pd.read_parquet(Path(d) / "steps.parquet") for d in df.episode_dir)
                result = replay(controller_dir, local)
                parity.append((name, model, result))
                numeric = local.select_dtypes("number").columns
                step_diff = float((local[numeric] - http[numeric]).abs().max().max())
                figures = [f for f in FIGURES if f in df]
                same = bool(np.array_equal(df[figures].iloc[0].to_numpy(), df[figures].iloc[1].to_numpy()))
                loop.append((name, len(local), step_diff, same, df[figures].iloc[0].to_dict(), local.equals(http)))
            # what a year costs over HTTP: the TRPO data-center case, A B B A on one worker
            name, model, _ = CASES[0]
            for proc in servers:  # the timing's server alone (one process each side, as a plant room would run it)
                proc.terminate()
            url, proc = serve(tmp / "controller-0", tmp)
            servers.append(proc)
            pairs = [("in process", policy_controller(str(ROOT / model))), ("over HTTP", http_controller(url))]
            costs = {"in process": [], "over HTTP": []}
            for k, which in enumerate([0, 1, 1, 0]):  # A B B A
                label, c = pairs[which]
                costs[label].append(timed(c, args.weather, args.days, tmp / f"time-{k}", None))
                log.info("timing %s: %.1f s", label, costs[label][-1])
        finally:
            for proc in servers:
                proc.terminate()
                proc.wait(timeout=30)
    write(args, parity, loop, costs, loop[0][1])


def write(args, parity, loop, costs, steps: int) -> None:
    when = f"{dt.date.today()}, {os.cpu_count()} cores, load average {os.getloadavg()[0]:.1f}"
    head = f"`python scripts/deploy_year.py --days {args.days} --weather {args.weather}` ({when})."
    args.out.mkdir(parents=True, exist_ok=True)
    rows = []
    for name, model, r in parity:
        worst = max(r["max_abs_diff"].values())
        each = ", ".join(f"{k} {v:.1e}" for k, v in r["max_abs_diff"].items())
        rows.append(f"| {name} | `{model}` | {r['steps']} | {worst:.1e} | {each} |")
    (args.out / "parity.md").write_text("\n".join([
        "# Export parity over a year",
        "",
        head + " Each policy's year in process (`evaluate --policy`), then its exported `controller.onnx` in "
        "onnxruntime on every recorded observation: the largest difference from the setpoint the policy gave "
        "(physical units: °C, kg/s). The requirement is 1e-5.",
        "",
        "| policy | model | steps | largest difference | per setpoint |",
        "| --- | --- | --- | --- | --- |",
        *rows, "",
    ]))  # fmt: skip
    rows = [
        f"| {name} | {n} | {'yes' if equal else 'no'} | {diff:.1e} | {'yes' if same else 'no'} | "
        f"{figs.get('power_kw', float('nan')):.2f} | {figs.get('in_band_pct', float('nan')):.2f} |"
        for name, n, diff, same, figs, equal in loop
    ]
    a, b = np.median(costs["in process"]), np.median(costs["over HTTP"])
    (args.out / "closed_loop.md").write_text("\n".join([
        "# Closed loop through the controller server",
        "",
        head + " Each policy's year twice in EnergyPlus: in process (`evaluate --policy`) and through "
        "`parallel-eplus serve` (`evaluate --controller-url`: every step's readings over HTTP, the setpoints back).",
        "",
        "| policy | steps | step tables identical | largest step difference | same table row | power (kW) "
        "| in band (%) |",
        "| --- | --- | --- | --- | --- | --- | --- |",
        *rows,
        "",
        "## What a year costs over HTTP",
        "",
        f"The TRPO data-center year alone on one worker, in turn (A B B A): in process "
        f"{', '.join(f'{t:.0f}' for t in costs['in process'])} s, over HTTP "
        f"{', '.join(f'{t:.0f}' for t in costs['over HTTP'])} s; median {a:.0f} s against {b:.0f} s "
        f"(x{b / a:.2f}, {(b - a) / steps * 1000:.2f} ms more per step). Measured on a shared machine.",
        "",
    ]))  # fmt: skip


if __name__ == "__main__":
    main()
