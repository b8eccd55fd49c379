"""What BOPTEST's API adds per control step, three ways, interleaved round by round so a busy machine meets each
alike. Two of them are `parallel-eplus bench --boptest`'s own (parallel_eplus/bench/boptest.py, reused here):

1. in process: engine/simulation.py stepped as a BOPTEST test steps it (`energyplus_steps`);
2. a BOPTEST test in process: deploy/boptest/test.py's `advance` (inputs parsed, the state built and kept), which
   `bench` cannot import (bench and deploy are peers): what the test's own work costs, HTTP aside;
3. over HTTP: `POST /advance/{testid}` to `parallel-eplus boptest` on loopback (`boptest_server`, `api_steps`).

Every action at the bench's constant action (the middle of its range), the data center's 15-minute steps by
default. Prints each way's wall time per step (the mean, and the median step), what it adds per step and its ratio
against 1. `bench --boptest` reports 1 against 3 step by step (p50, p99) in bench.json; this adds 2 beside them.

    .venv/bin/python studies/boptest/bench_advance.py --days 365 --rounds 1
"""

from __future__ import annotations

import argparse
import statistics
import sys
import tempfile
import time
from pathlib import Path

from parallel_eplus.bench.boptest import DEFAULT_TESTCASE, api_steps, boptest_server, energyplus_steps
from parallel_eplus.bench.config import BenchConfig, bench_building
from parallel_eplus.buildings.scaling import denormalize


def in_process_test(cfg: BenchConfig, steps: int) -> list[float]:
    from parallel_eplus.deploy.boptest.test import BoptestTest

    name = bench_building(cfg).spec.path.stem if cfg.building else DEFAULT_TESTCASE
    t = BoptestTest(name, cfg.building or name, cfg.weather)
    u = {p.name: denormalize(cfg.action, p.minimum, p.maximum) for p in t.points.inputs}
    u |= {a: 1 for a in t.points.activations()}
    t.initialize(0, 0)
    each = []
    try:
        for _ in range(steps):
            t1 = time.perf_counter()
            if not t.advance(dict(u))[1]:
                break
            each.append(time.perf_counter() - t1)
    finally:
        t.close()
    return each


def rounds(cfg: BenchConfig, tmp: Path, port: int, testcase: str, per: dict, medians: dict, counts: dict) -> None:
    """`cfg.repeats` rounds of the three ways, each way's ms per step (mean, median) appended to `per`, `medians`."""
    for r in range(cfg.repeats):
        alone = energyplus_steps(cfg, tmp / f"energyplus{r}")
        runs = {"in process": alone, "test in process": in_process_test(cfg, len(alone)),
                "over HTTP": api_steps(port, testcase, cfg, len(alone))}  # fmt: skip
        for name, each in runs.items():
            elapsed, steps = sum(each), len(each)
            per[name].append(elapsed / steps * 1000)
            medians[name].append(statistics.median(each) * 1000)
            counts[name] = steps
            print(f"round {r + 1}: {name}: {steps} steps in {elapsed:.1f} s, {elapsed / steps * 1000:.3f} ms/step "
                  f"(median step {medians[name][-1]:.3f} ms)", flush=True)  # fmt: skip


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--days", type=int, default=365)
    p.add_argument("--rounds", type=int, default=1)
    p.add_argument("--building", help="a spec path or built-in name (default: the data center)")
    p.add_argument("--weather", default="CA")
    args = p.parse_args()
    cfg = BenchConfig(raw_days=args.days, weather=args.weather, building=args.building, repeats=args.rounds)
    per: dict[str, list[float]] = {"in process": [], "test in process": [], "over HTTP": []}
    medians: dict[str, list[float]] = {k: [] for k in per}
    counts = {}
    with tempfile.TemporaryDirectory(prefix="bench-advance-") as folder:
        tmp = Path(folder)
        with boptest_server(cfg, tmp / "server") as (port, testcase):
            rounds(cfg, tmp, port, testcase, per, medians, counts)
    base, base_median = statistics.median(per["in process"]), statistics.median(medians["in process"])
    print(f"\n{args.days} days, {testcase} on {args.weather}, median of {args.rounds} round(s):")
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
