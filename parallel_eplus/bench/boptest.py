"""`parallel-eplus bench --boptest`: what BOPTEST's API (`parallel-eplus boptest`, deploy/boptest/) adds per control
step over EnergyPlus stepped alone, in process, on the same episode (issue 88's aim: at most 2 ms a step).

Two runs of the bench's building and weather, `raw_days` of the model's timesteps from January 1, every action at
the bench's constant action (`action`, normalized: the middle of each action's range by default), alternated repeat
by repeat so a busy machine meets both alike:

1. EnergyPlus alone: engine/simulation.py stepped in process as a BOPTEST test steps it (the same episode settings:
   the building's own controls under the actuators, `relinquish`, the Python bridge), each `send` + `receive` timed;
2. over the API: `parallel-eplus boptest` in a process of its own on loopback (bench imports no deploy: they are
   peers), one test selected and initialized at 0 s, then one `POST /advance/{testid}` per timestep on one
   kept-alive connection, every input activated at the same value (in SI, from `GET /inputs`' bounds), each
   request's round trip timed as a client sees it.

Step k of both is the same simulated step under the same action, so the overhead is taken step by step: `added_ms`
is the distribution of (round trip k - EnergyPlus step k) (mean, p50, p99); beside it each run's own figures and the
ratio of the means. The episode's last step (where EnergyPlus writes its files) is left out of both. Medians over
the repeats; the load average before and after, since the machine's other work inflates every wall time here.
"""

from __future__ import annotations

import http.client
import json
import logging
import math
import os
import socket
import statistics
import subprocess
import sys
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import numpy as np

from parallel_eplus.bench.config import BenchConfig, bench_building
from parallel_eplus.buildings.scaling import denormalize
from parallel_eplus.engine.config import SimulationConfig

log = logging.getLogger(__name__)

DEFAULT_TESTCASE = "datacenter-2zone"  # the bench's default building, as the server names it
START_TIMEOUT_S = 120.0


def energyplus_steps(cfg: BenchConfig, workdir: Path) -> list[float]:
    """Wall seconds of each step of the bench's episode stepped in process as a BOPTEST test steps it (its last,
    terminal step left out)."""
    from parallel_eplus.engine.simulation import Simulation

    building = bench_building(cfg)
    n = len(building.actions)
    config = SimulationConfig(
        weather=cfg.weather, building=str(building.spec.path), run_days=cfg.raw_days, relinquish=True,
        native_bridge=False, prepare_next=False, fork_episodes=False, keep_episodes=1,
        initial_action=(math.nan,) * n, output_dir=str(workdir),
    )  # fmt: skip  # deploy/boptest/test.py's `initialize` (start 0, no warm-up)
    sim = Simulation(config, building=building)
    action, each = [cfg.action] * n, []
    try:
        sim.start()
        while True:
            t = time.perf_counter()
            sim.send(action)
            done = sim.receive()[2]
            if done:
                break
            each.append(time.perf_counter() - t)
    finally:
        sim.close()
    return each


class _Client:
    """BOPTEST's API on loopback: one kept-alive connection; each answer's payload, or an error naming the request."""

    def __init__(self, port: int):
        self.conn = http.client.HTTPConnection("127.0.0.1", port, timeout=300)

    def __call__(self, method: str, path: str, body: dict | None = None):
        data = json.dumps(body).encode() if body is not None else None
        self.conn.request(method, path, data, {"Content-Type": "application/json"} if data else {})
        r = self.conn.getresponse()
        text = r.read()
        answer = json.loads(text) if r.getheader("content-type", "").startswith("application/json") else text
        if r.status != 200:
            raise RuntimeError(f"{method} {path}: {r.status} {answer}")
        return answer["payload"] if isinstance(answer, dict) and "payload" in answer else answer

    def close(self) -> None:
        self.conn.close()


def api_steps(port: int, testcase: str, cfg: BenchConfig, steps: int) -> list[float]:
    """Wall seconds of each of `steps` round trips of `POST /advance` (one timestep each, every input activated at
    the bench's action) on a test of `testcase` selected from the server at `port`."""
    call = _Client(port)
    testid = call("POST", f"/testcases/{testcase}/select", {"weather": cfg.weather})["testid"]
    try:
        inputs = call("GET", f"/inputs/{testid}")
        u = {name: 1 if name.endswith("_activate") else denormalize(cfg.action, m["Minimum"], m["Maximum"])
             for name, m in inputs.items()}  # fmt: skip
        call("PUT", f"/initialize/{testid}", {"start_time": 0, "warmup_period": 0})
        each = []
        for _ in range(steps):
            t = time.perf_counter()
            state = call("POST", f"/advance/{testid}", u)
            each.append(time.perf_counter() - t)
            if not state:  # the run period's end: not a step
                each.pop()
                break
    finally:
        try:
            call("PUT", f"/stop/{testid}")
        except (OSError, RuntimeError) as e:  # the server's end stops it anyway
            log.warning("could not stop BOPTEST test %s: %s", testid, e)
        call.close()
    return each


@contextmanager
def boptest_server(cfg: BenchConfig, workdir: Path) -> Iterator[tuple[int, str]]:
    """`parallel-eplus boptest` serving the bench's building on a free loopback port, one worker: (port, test case
    name); stopped (and its EnergyPlus processes with it) at the end."""
    workdir.mkdir(parents=True, exist_ok=True)
    command = [sys.executable, "-m", "parallel_eplus.cli", "boptest", "--workers", "1", "--cache", str(workdir)]
    testcase = DEFAULT_TESTCASE
    if cfg.building:  # a spec of its own: served from a folder holding a link to it (its relative paths intact)
        spec = bench_building(cfg).spec.path
        testcase = spec.stem
        specs = workdir / "specs"
        specs.mkdir(exist_ok=True)
        (specs / spec.name).symlink_to(spec.resolve())
        command += ["--specs", str(specs)]
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    log_path = workdir / "boptest-server.log"
    with log_path.open("w") as out:
        server = subprocess.Popen([*command, "--port", str(port)], stdout=out, stderr=subprocess.STDOUT)
    try:
        deadline = time.monotonic() + START_TIMEOUT_S
        while True:
            try:
                c = _Client(port)
                c("GET", "/version")
                c.close()
                break
            except OSError:
                if server.poll() is not None or time.monotonic() > deadline:
                    raise RuntimeError(
                        f"parallel-eplus boptest did not start (exit {server.poll()}): {log_path.read_text()[-2000:]}"
                    ) from None
                time.sleep(0.3)
        yield port, testcase
    finally:
        server.terminate()
        try:
            server.wait(timeout=60)
        except subprocess.TimeoutExpired:
            server.kill()
            server.wait()


def _ms(seconds) -> dict[str, float]:
    ms = np.asarray(seconds, dtype=float) * 1000
    return {"mean": float(ms.mean()), "p50": float(np.percentile(ms, 50)), "p99": float(np.percentile(ms, 99))}


def advance_overhead(cfg: BenchConfig, workdir: Path) -> dict:
    """What `POST /advance` adds per control step over EnergyPlus stepped alone in process (module doc): ms per step
    (mean, p50, p99) of each run and of their step-by-step difference, medians over `cfg.repeats`."""
    building = bench_building(cfg)
    load_before = os.getloadavg()[0]
    runs: list[dict] = []
    with boptest_server(cfg, workdir / "server") as (port, testcase):
        for i in range(cfg.repeats):
            alone = energyplus_steps(cfg, workdir / f"energyplus{i}")
            api = api_steps(port, testcase, cfg, len(alone))
            n = min(len(alone), len(api))
            if n == 0:
                raise RuntimeError(f"no step to compare: {len(alone)} in process, {len(api)} over the API")
            added = np.subtract(api[:n], alone[:n])
            r = {"steps": n, "energyplus_ms": _ms(alone[:n]), "api_ms": _ms(api[:n]), "added_ms": _ms(added)}
            runs.append(r)
            log.info("boptest advance, repeat %d: %d steps, %.3f ms in process, %.3f over the API: +%.3f ms (p50 "
                     "+%.3f, p99 +%.3f)", i + 1, n, r["energyplus_ms"]["mean"], r["api_ms"]["mean"],
                     r["added_ms"]["mean"], r["added_ms"]["p50"], r["added_ms"]["p99"])  # fmt: skip
    out: dict = {"building": testcase, "weather": cfg.weather, "days": cfg.raw_days, "repeats": cfg.repeats,
                 "step_s": 86400 / building.steps_per_day, "steps": runs[0]["steps"]}  # fmt: skip
    for key in ("energyplus_ms", "api_ms", "added_ms"):
        out[key] = {s: statistics.median(r[key][s] for r in runs) for s in ("mean", "p50", "p99")}
    out["ratio"] = statistics.median(r["api_ms"]["mean"] / r["energyplus_ms"]["mean"] for r in runs)
    out["load_average"] = [round(load_before, 2), round(os.getloadavg()[0], 2)]
    return out


def overhead_rows(b: dict) -> list[tuple[str, str, str]]:
    """`bench`'s table rows for `advance_overhead`'s figures."""
    a, e = b["added_ms"], b["energyplus_ms"]
    return [
        (f"BOPTEST API, POST /advance ({b['step_s'] / 60:g}-min steps)",
         f"p50 +{a['p50']:.2f} / p99 +{a['p99']:.2f} ms",
         f"mean +{a['mean']:.2f} over {e['mean']:.2f} ms in process, x{b['ratio']:.2f} (target <= +2 ms); load "
         f"{b['load_average'][0]:.1f}-{b['load_average'][1]:.1f}"),
    ]  # fmt: skip
