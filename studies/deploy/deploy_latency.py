"""Latency of a served controller over loopback: `POST /act` round trips, p50/p90/p99, written to results/deploy/.

Exports a committed policy (results/paper/models/paper-ca-co-fl-time: TRPO, 10 inputs with the clock's) or, with
`--planner`, a committed planner (the paper's data center, seed 0: its ensemble in onnxruntime, 256 candidates x 3
CEM iterations over 8 steps), starts `parallel-eplus serve` in its own process, sends a bounded number of requests
over one kept-alive connection (as `evaluate --controller-url` does: a planner's carry the last setpoints, the
weather file's coming steps as the forecast and the last plan) and times each; then the controller alone in this
process, for its share. `--load N` keeps N other processes busy meanwhile (a machine doing other work).

    .venv/bin/python studies/deploy/deploy_latency.py [--planner] [--load 2] [--requests 5000] [--out FILE.md]
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

ROOT = Path(__file__).resolve().parents[2]
MODEL = ROOT / "results" / "paper" / "models" / "paper-ca-co-fl-time"
PLANNER = ROOT / "results" / "model-based" / "datacenter-2zone" / "runs" / "datacenter-2zone-mpc-seed0"
LAST = {"west_setpoint_c": 12.0, "east_setpoint_c": 12.0, "west_fan_kg_s": 4.0, "east_fan_kg_s": 4.0}
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


class Requests:
    """Request i of a year's worth of steps: a policy's readings and time, or a planner's with the rest it needs."""

    def __init__(self, planner: bool):
        self.planner, self.start = planner, dt.datetime(2013, 1, 1)
        if planner:
            from parallel_eplus.buildings.building import weather_path
            from parallel_eplus.buildings.weather.forecast import WEATHER, PerfectForecast

            self.names, self.file = WEATHER, PerfectForecast(weather_path("datacenter-2zone", "CA"))
        self.plan, self.fallbacks = None, 0

    def body(self, i: int) -> dict:
        when = self.start + dt.timedelta(minutes=15 * i)
        body = {"time": when.isoformat(), "sensors": READINGS}
        if self.planner:
            values = self.file.truth([when + dt.timedelta(minutes=15 * k) for k in range(9)])
            forecast = {n: values[1:, j].tolist() for j, n in enumerate(self.names)}
            # the outdoor sensor agrees with the weather file, so every answer is a plan, never the fallback's rule
            body["sensors"] = READINGS | {"outdoor_temp_c": float(values[0, 0])}
            body |= {"last_setpoints": LAST, "forecast": forecast, "plan": self.plan}
        return body

    def answered(self, answer: dict) -> None:
        self.plan = answer.get("plan")
        self.fallbacks += bool(answer.get("fallback"))


def busy(n: int) -> list[subprocess.Popen]:
    """`n` processes spinning on a core each until stopped."""
    return [subprocess.Popen([sys.executable, "-c", "while True: pass"]) for _ in range(n)]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--requests", type=int, default=5000)
    parser.add_argument("--warmup", type=int, default=200)
    parser.add_argument("--planner", action="store_true", help="a committed planner instead of a policy network")
    parser.add_argument("--load", type=int, default=0, help="other processes kept busy meanwhile")
    parser.add_argument("--out", type=Path)
    args = parser.parse_args()
    args.out = args.out or ROOT / "results" / "deploy" / ("planner_latency.md" if args.planner else "latency.md")
    from parallel_eplus.deploy.export.policy import export

    requests = Requests(args.planner)
    with tempfile.TemporaryDirectory(prefix="deploy-latency-") as tmp:
        export(PLANNER if args.planner else MODEL, Path(tmp), **({"record_days": 2} if args.planner else {}))
        port = free_port()
        cli = [sys.executable, "-m", "parallel_eplus.cli", "serve", tmp, "--port", str(port)]
        log = open(Path(tmp) / "server.log", "w")  # noqa: SIM115 - every request is logged: a pipe would fill up
        proc = subprocess.Popen(cli, stdout=log, stderr=subprocess.STDOUT, text=True)
        spinning = busy(args.load)
        try:
            wait_up(port, proc)
            conn = http.client.HTTPConnection("127.0.0.1", port, timeout=10)
            times = []
            for i in range(args.warmup + args.requests):  # bounded: a fixed number of requests
                body = json.dumps(requests.body(i))
                t0 = time.perf_counter()
                conn.request("POST", "/act", body, {"Content-Type": "application/json"})
                response = conn.getresponse()
                answer = response.read()
                times.append(time.perf_counter() - t0)
                if response.status != 200:
                    raise SystemExit(f"request {i}: {response.status} {answer[:200]!r}")
                requests.answered(json.loads(answer))
            conn.close()
            http_ms = np.array(times[args.warmup :]) * 1000
            alone_ms = alone(Path(tmp), requests, args)
            load = os.getloadavg()
        finally:
            for p in spinning:
                p.kill()
                p.wait()
            proc.terminate()
            proc.wait(timeout=30)
            log.close()
    h, g = percentiles(http_ms), percentiles(alone_ms)
    what = "the planner's plan (numpy and onnxruntime)" if args.planner else "onnxruntime session.run"
    rows = [
        ("POST /act over loopback (one kept-alive connection)", h),
        (f"{what} alone (in process)", g),
    ]
    text = "\n".join(
        [
            "# Controller latency",
            "",
            f"`python studies/deploy/deploy_latency.py{' --planner' if args.planner else ''} --load {args.load} "
            f"--requests {args.requests}` on {dt.date.today()}: {args.requests} requests after {args.warmup} of "
            f"warm-up; {os.cpu_count()} cores, {args.load} other processes kept busy, load average {load[0]:.1f} at "
            "the end.",
            "",
            "| what | p50 (ms) | p90 (ms) | p99 (ms) | max (ms) |",
            "| --- | --- | --- | --- | --- |",
            *(f"| {name} | {r['p50']:.3f} | {r['p90']:.3f} | {r['p99']:.3f} | {r['max']:.1f} |" for name, r in rows),
            "",
            f"Throughput over the connection: {args.requests / http_ms.sum() * 1000:.0f} requests/s. A control step is "
            "900 s; the request is a vanishing share of it."
            + (f" Answers that fell back to the rule (not plans), both runs: {requests.fallbacks}." * args.planner),
            "",
        ]
    )
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(text)
    print(text)


def alone(folder: Path, requests: Requests, args) -> np.ndarray:
    """Milliseconds of the controller itself per request, in this process (no HTTP)."""
    from parallel_eplus.deploy.serve.server import load_runtime

    runtime = load_runtime(folder)
    requests.plan = None
    times = []
    for i in range(args.warmup + args.requests):
        body = requests.body(i)
        t0 = time.perf_counter()
        answer = runtime.act(body)
        times.append(time.perf_counter() - t0)
        requests.answered(answer)
    return np.array(times[args.warmup :]) * 1000


if __name__ == "__main__":
    main()
