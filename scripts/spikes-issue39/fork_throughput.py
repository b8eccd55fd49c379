"""Spike (issue 39, part 2c): EnergyPlus-side throughput with both cores busy, as in training with 2 workers.

Two processes at once, each running `--episodes` consecutive 1-day episodes (spike/fork_episode.py's modes: a new
state per episode in a warm process, or forks of a parked, warmed-up one), against two processes each running one
year: simulated steps per second of wall, rounds interleaved. No learner and no pipes: the EnergyPlus side's own
ceiling for short episodes relative to a year.

    python scripts/spikes-issue39/fork_throughput.py --episodes 16 --rounds 2
"""

from __future__ import annotations

import argparse
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).with_name("fork_episode.py")


def both(mode: str, days: int, episodes: int, work: Path) -> float:
    """Wall seconds for two processes at once, each `episodes` episodes of `days` days (+1 first, fresh only)."""
    procs = []
    t0 = time.perf_counter()
    for w in range(2):
        d = work / f"{mode}{days}-{w}"
        d.mkdir(parents=True)
        cmd = [sys.executable, str(HERE), "--mode", mode, "--work", str(d), "--episodes", str(episodes), "--days",
               str(days)]  # fmt: skip
        procs.append(subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL))
    for p in procs:
        assert p.wait() == 0
    return time.perf_counter() - t0


def main() -> None:
    p = argparse.ArgumentParser()
    p.add_argument("--episodes", type=int, default=16)
    p.add_argument("--rounds", type=int, default=2)
    args = p.parse_args()
    n = args.episodes
    rates: dict[str, list[float]] = {"fresh": [], "fork": [], "year": []}
    with tempfile.TemporaryDirectory(prefix="fork-throughput-") as tmp:
        for r in range(args.rounds):
            work = Path(tmp) / f"r{r}"
            # fresh runs n+1 episodes (its first in a fresh address space), fork parks once then forks n: both
            # pay their process's start-up once, as a worker does
            rates["fresh"].append(2 * (n + 1) * 96 / both("fresh", 1, n, work))
            rates["fork"].append(2 * n * 96 / both("fork", 1, n, work))
            rates["year"].append(2 * 365 * 96 / both("fresh", 365, 0, work))
            print(f"round {r}: steps/s of 2 processes: fresh 1-day {rates['fresh'][-1]:.0f}, fork 1-day "
                  f"{rates['fork'][-1]:.0f}, year {rates['year'][-1]:.0f}", flush=True)  # fmt: skip
    med = statistics.median
    for k in ("fresh", "fork"):
        ratio = med(a / b for a, b in zip(rates[k], rates["year"], strict=True))
        print(f"1-day {k} / year: {ratio:.2f}")


if __name__ == "__main__":
    main()
