"""What BOPTEST's API adds per control step: a run of 15-minute steps of the data center (its own controls
overwritten by a constant setpoint every step) stepped three ways, interleaved round by round so a busy machine
meets each alike:

1. in process: engine/simulation.py stepped as `evaluate` steps it (the same episode settings a test uses:
   the building's own controls under the actuators, `relinquish`);
2. a BOPTEST test in process: deploy/boptest/test.py's `advance` (inputs parsed, the state built and kept);
3. over HTTP: `POST /advance/{testid}` to `parallel-eplus boptest` on loopback, one kept-alive connection.

Prints each way's wall time per step (after initialize; the mean, and the median step) and what the API adds per
step, and its ratio, against 1.

    .venv/bin/python studies/boptest/bench_advance.py --days 365 --rounds 1
"""

from __future__ import annotations

import argparse
import http.client
import json
import math
import socket
import statistics
import subprocess
import sys
import time

BUILDING = "datacenter-2zone"
INPUT = {"west_setpoint_u": 296.15, "west_setpoint_activate": 1}  # 23 °C, every step


def in_process(days: int) -> tuple[float, int]:
    from parallel_eplus.buildings.building import load_building
    from parallel_eplus.buildings.scaling import normalize
    from parallel_eplus.engine.config import SimulationConfig
    from parallel_eplus.engine.simulation import Simulation

    n_actions = len(load_building(BUILDING).actions)
    config = SimulationConfig(weather="CA", building=BUILDING, run_days=days, relinquish=True, native_bridge=False,
                              prepare_next=False, fork_episodes=False,
                              initial_action=(math.nan,) * n_actions)  # fmt: skip
    sim = Simulation(config)
    e = sim.elements[0]
    action = [normalize(23.0, e.low, e.high)] + [math.nan] * (n_actions - 1)
    sim.start()
    t0, each = time.perf_counter(), []
    while True:
        t = time.perf_counter()
        sim.send(action)
        _, _, done, _ = sim.receive()
        each.append(time.perf_counter() - t)
        if done:
            break
    elapsed = time.perf_counter() - t0
    sim.close()
    return elapsed, each


def test_in_process(days: int) -> tuple[float, int]:
    from parallel_eplus.deploy.boptest.test import BoptestTest

    t = BoptestTest(BUILDING, BUILDING, "CA")
    t.initialize(0, 0, end_time=days * 86400)
    t0, each = time.perf_counter(), []
    while True:
        t1 = time.perf_counter()
        if not t.advance(dict(INPUT))[1]:
            break
        each.append(time.perf_counter() - t1)
    elapsed = time.perf_counter() - t0
    t.close()
    return elapsed, each


def over_http(port: int, days: int) -> tuple[float, int]:
    conn = http.client.HTTPConnection("127.0.0.1", port, timeout=300)

    def call(method, path, body=None):
        conn.request(method, path, json.dumps(body or {}).encode(), {"Content-Type": "application/json"})
        return json.loads(conn.getresponse().read())

    testid = call("POST", f"/testcases/{BUILDING}/select", {"weather": "CA"})["testid"]
    call("PUT", f"/initialize/{testid}", {"start_time": 0, "warmup_period": 0})
    end = days * 86400
    t0, each, now = time.perf_counter(), [], 0.0
    while now < end:
        t1 = time.perf_counter()
        state = call("POST", f"/advance/{testid}", INPUT)["payload"]
        if not state:  # the run period's end
            break
        each.append(time.perf_counter() - t1)
        now = state["time"]
    elapsed = time.perf_counter() - t0
    conn.request("PUT", f"/stop/{testid}")
    conn.getresponse().read()
    return elapsed, each


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--days", type=int, default=365)
    p.add_argument("--rounds", type=int, default=1)
    args = p.parse_args()
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    server = subprocess.Popen([sys.executable, "-m", "parallel_eplus.cli", "boptest", "--port", str(port),
                               "--workers", "1"], stderr=subprocess.DEVNULL)  # fmt: skip
    try:
        for _ in range(600):
            try:
                http.client.HTTPConnection("127.0.0.1", port, timeout=2).request("GET", "/version")
                break
            except OSError:
                time.sleep(0.2)
        per: dict[str, list[float]] = {"in process": [], "test in process": [], "over HTTP": []}
        medians: dict[str, list[float]] = {k: [] for k in per}
        counts = {}
        for r in range(args.rounds):
            for name, run in (("in process", lambda: in_process(args.days)),
                              ("test in process", lambda: test_in_process(args.days)),
                              ("over HTTP", lambda: over_http(port, args.days))):  # fmt: skip
                elapsed, each = run()
                steps = len(each)
                per[name].append(elapsed / steps * 1000)
                medians[name].append(statistics.median(each) * 1000)
                counts[name] = steps
                print(f"round {r + 1}: {name}: {steps} steps in {elapsed:.1f} s, {elapsed / steps * 1000:.3f} ms/step "
                      f"(median step {medians[name][-1]:.3f} ms)", flush=True)  # fmt: skip
    finally:
        server.terminate()
        server.wait(timeout=60)
    base, base_median = statistics.median(per["in process"]), statistics.median(medians["in process"])
    print(f"\n{args.days} days of 15-minute steps, {BUILDING}, median of {args.rounds} round(s):")
    print(f"  {'':16s} {'mean':>7s}  {'added':>7s}  {'ratio':>5s}  {'median':>7s}  {'added':>7s}")
    for name, values in per.items():
        ms, med = statistics.median(values), statistics.median(medians[name])
        print(
            f"  {name:16s} {ms:7.3f}  {ms - base:+7.3f}  {ms / base:5.2f}  {med:7.3f}  {med - base_median:+7.3f}  "
            f"ms/step ({counts[name]} steps)"
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
