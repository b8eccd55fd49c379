"""Latency of a served controller over loopback: `POST /act` round trips, p50/p90/p99, written to results/deploy/.

Exports a committed policy (results/paper/models/paper-ca-co-fl-time: TRPO, 10 inputs with the clock's), starts
`parallel-eplus serve` in its own process, sends a bounded number of requests over one kept-alive connection (as
`evaluate --controller-url` does) and times each; then onnxruntime alone in this process, for the graph's share.

    .venv/bin/python scripts/deploy_latency.py [--requests 5000] [--out results/deploy/latency.md]
"""

from __future__ import annotations

import argparse
import datetime as dt
import http.client
import json
import os
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
MODEL = ROOT / "results" / "paper" / "models" / "paper-ca-co-fl-time"
READINGS = {
    "outdoor_temp_c": 12.5, "west_temp_c": 23.1, "east_temp_c": 23.4,
    "power_w": 95000.0, "it_power_w": 70000.0, "hvac_power_w": 25000.0,
}  # fmt: skip


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def wait_up(port: int, proc: subprocess.Popen, limit_s: float = 60.0) -> None:
    deadline = time.monotonic() + limit_s
    while time.monotonic() < deadline:
        if proc.poll() is not None:
            raise SystemExit(f"the server exited with {proc.returncode}")
        try:
            conn = http.client.HTTPConnection("127.0.0.1", port, timeout=2)
            conn.request("GET", "/health")
            if conn.getresponse().status == 200:
                return
        except OSError:
            time.sleep(0.2)
    raise SystemExit("the server did not answer within a minute")


def percentiles(ms: np.ndarray) -> dict:
    return {f"p{p}": float(np.percentile(ms, p)) for p in (50, 90, 99)} | {"max": float(ms.max())}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--requests", type=int, default=5000)
    parser.add_argument("--warmup", type=int, default=200)
    parser.add_argument("--out", type=Path, default=ROOT / "results" / "deploy" / "latency.md")
    args = parser.parse_args()
    from parallel_eplus.deploy.export import export

    with tempfile.TemporaryDirectory(prefix="deploy-latency-") as tmp:
        export(MODEL, Path(tmp))
        port = free_port()
        cli = [sys.executable, "-m", "parallel_eplus.cli", "serve", tmp, "--port", str(port)]
        log = open(Path(tmp) / "server.log", "w")  # noqa: SIM115 - every request is logged: a pipe would fill up
        proc = subprocess.Popen(cli, stdout=log, stderr=subprocess.STDOUT, text=True)
        try:
            wait_up(port, proc)
            conn = http.client.HTTPConnection("127.0.0.1", port, timeout=10)
            start = dt.datetime(2013, 1, 1)
            times = []
            for i in range(args.warmup + args.requests):  # bounded: a fixed number of requests
                body = json.dumps({"time": (start + dt.timedelta(minutes=15 * i)).isoformat(), "sensors": READINGS})
                t0 = time.perf_counter()
                conn.request("POST", "/act", body, {"Content-Type": "application/json"})
                response = conn.getresponse()
                response.read()
                times.append(time.perf_counter() - t0)
                if response.status != 200:
                    raise SystemExit(f"request {i}: {response.status}")
            conn.close()
        finally:
            proc.terminate()
            proc.wait(timeout=30)
            log.close()
        http_ms = np.array(times[args.warmup :]) * 1000
        import onnxruntime as ort

        from parallel_eplus.deploy.contract import Contract

        options = ort.SessionOptions()
        options.intra_op_num_threads = 1
        session = ort.InferenceSession(f"{tmp}/controller.onnx", options, providers=["CPUExecutionProvider"])
        contract = Contract.read(Path(tmp))
        obs = contract.observation({"time": "2013-07-02T14:15:00", "sensors": READINGS})
        graph = []
        for _ in range(args.warmup + args.requests):
            t0 = time.perf_counter()
            session.run(["setpoints"], {"observation": obs})
            graph.append(time.perf_counter() - t0)
        graph_ms = np.array(graph[args.warmup :]) * 1000
    h, g = percentiles(http_ms), percentiles(graph_ms)
    load = os.getloadavg()
    rows = [
        ("POST /act over loopback (one kept-alive connection)", h),
        ("onnxruntime session.run alone (in process)", g),
    ]
    text = "\n".join(
        [
            "# Controller latency",
            "",
            f"`python scripts/deploy_latency.py --requests {args.requests}` on {dt.date.today()}: "
            f"{args.requests} requests after {args.warmup} of warm-up; {os.cpu_count()} cores, "
            f"load average {load[0]:.1f} "
            "(a machine shared with other sessions: figures under load).",
            "",
            "| what | p50 (ms) | p90 (ms) | p99 (ms) | max (ms) |",
            "| --- | --- | --- | --- | --- |",
            *(f"| {name} | {r['p50']:.3f} | {r['p90']:.3f} | {r['p99']:.3f} | {r['max']:.1f} |" for name, r in rows),
            "",
            f"Throughput over the connection: {args.requests / http_ms.sum() * 1000:.0f} requests/s. A control step is "
            "900 s; the request is a vanishing share of it.",
            "",
        ]
    )
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(text)
    print(text)


if __name__ == "__main__":
    main()
