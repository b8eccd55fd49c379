"""N tests at once through `parallel-eplus boptest` (each two days of the small office at 30-minute steps, the
heating setpoint overwritten every fourth step), against one test alone: the same KPIs (time_rat aside), and no
EnergyPlus process of the server left once they are stopped.

    .venv/bin/parallel-eplus boptest --port 8000 --workers 8 &
    .venv/bin/python studies/boptest/concurrent_check.py --port 8000 --tests 8
"""

from __future__ import annotations

import argparse
import http.client
import json
import subprocess
import sys
import threading
import time

DAY = 86400


def client(port: int):
    conn = http.client.HTTPConnection("127.0.0.1", port, timeout=600)

    def call(method: str, path: str, body=None):
        conn.request(method, path, json.dumps(body or {}).encode(), {"Content-Type": "application/json"})
        r = conn.getresponse()
        text = r.read()
        return json.loads(text) if r.getheader("content-type", "").startswith("application/json") else text.decode()

    return call


def one_test(port: int, out: dict, key) -> None:
    call = client(port)
    testid = call("POST", "/testcases/office-small/select", {"weather": "IL"})["testid"]
    call("PUT", f"/initialize/{testid}", {"start_time": 10 * DAY, "warmup_period": DAY})
    call("PUT", f"/step/{testid}", {"step": 1800})
    steps = 0
    while True:
        u = {"heating_setpoint_u": 294.15, "heating_setpoint_activate": 1} if steps % 4 == 0 else {}
        state = call("POST", f"/advance/{testid}", u)["payload"]
        steps += 1
        if state["time"] >= 12 * DAY:
            break
    out[key] = (steps, call("GET", f"/kpi/{testid}")["payload"])
    call("PUT", f"/stop/{testid}")


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--port", type=int, default=8000)
    p.add_argument("--tests", type=int, default=8)
    p.add_argument("--server-pid", type=int, help="the server's pid: count its EnergyPlus children at the end")
    args = p.parse_args()
    t0 = time.perf_counter()
    alone: dict = {}
    one_test(args.port, alone, 0)
    t1 = time.perf_counter()
    out: dict = {}
    threads = [threading.Thread(target=one_test, args=(args.port, out, i)) for i in range(args.tests)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    t2 = time.perf_counter()
    ref = alone[0][1]
    equal = len(out) == args.tests and all(o[1][k] == ref[k] for o in out.values() for k in ref if k != "time_rat")
    report = {"alone_s": round(t1 - t0, 1), "concurrent_s": round(t2 - t1, 1), "tests": len(out),
              "steps": sorted(o[0] for o in out.values()), "kpis_equal_alone": equal, "kpis": ref}  # fmt: skip
    if args.server_pid:
        found = subprocess.run(["pgrep", "-P", str(args.server_pid), "-f", "eplus_side.callback"],
                               capture_output=True, text=True).stdout.split()  # fmt: skip
        report["energyplus_left"] = len(found)
    print(json.dumps(report, indent=1))
    return 0 if equal else 1


if __name__ == "__main__":
    sys.exit(main())
