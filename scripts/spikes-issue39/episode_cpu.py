"""CPU seconds per short episode, both sides, forked against long-lived (issue 39): what a load cannot blur.

One env runs `--episodes` consecutive episodes (after two to warm up); the EnergyPlus side's CPU is read from /proc:
a template's own time plus its reaped children's (cutime, cstime: the forked episodes), or the two long-lived
processes' own time; the env's from getrusage. Also the forked episodes' minor page faults (copy on write).

    python scripts/spikes-issue39/episode_cpu.py --days 1 --episodes 30
"""

from __future__ import annotations

import argparse
import os
import resource
import tempfile
import time
from pathlib import Path

import numpy as np

from parallel_eplus import EnergyPlusEnv

TICK = os.sysconf("SC_CLK_TCK")


def proc_times(pid: int) -> np.ndarray:
    """utime, stime, cutime, cstime (s) and the reaped children's minor faults of one process."""
    f = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return np.array([int(x) / TICK for x in f[11:15]] + [int(f[8])])


def energyplus_side(env: EnergyPlusEnv) -> np.ndarray:
    sim = env.sim
    if sim.supply.templates is not None:
        pids = [t.proc.pid for t in sim.supply.templates.by_epw.values()]
    else:
        pids = [p.warm.proc.pid for p in (sim.process, sim.supply.spare) if p.warm.proc is not None]
    return sum(proc_times(p) for p in pids)


def run(days: int, episodes: int, fork: bool) -> dict:
    with tempfile.TemporaryDirectory(prefix="parallel-eplus-cpu-") as tmp:
        env = EnergyPlusEnv(weather="CA", run_days=days, output_dir=tmp, keep_episodes=0, energyplus_csv=False,
                            fork_episodes=fork)  # fmt: skip
        a = np.zeros(4, np.float32)
        try:
            for k in range(episodes + 2):
                if k == 2:  # warmed up: both processes (or the template) started
                    side0, me0, t0 = energyplus_side(env), resource.getrusage(resource.RUSAGE_SELF), time.perf_counter()
                env.reset()
                terminated = False
                while not terminated:
                    _, _, terminated, _, _ = env.step(a)
            env.sim.supply.settle()
            side1, me1, t1 = energyplus_side(env), resource.getrusage(resource.RUSAGE_SELF), time.perf_counter()
        finally:
            env.close()
    d = (side1 - side0) / episodes
    return {
        "mode": "forked" if fork else "long-lived", "days": days,
        "energyplus_side_ms": 1e3 * float(d[:4].sum()), "own_user_ms": 1e3 * d[0], "own_sys_ms": 1e3 * d[1],
        "children_user_ms": 1e3 * d[2], "children_sys_ms": 1e3 * d[3], "children_minor_faults": d[4],
        "env_ms": 1e3 * (me1.ru_utime + me1.ru_stime - me0.ru_utime - me0.ru_stime) / episodes,
        "wall_ms": 1e3 * (t1 - t0) / episodes,
    }  # fmt: skip


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--days", type=int, nargs="+", default=[1, 7])
    p.add_argument("--episodes", type=int, default=20)
    p.add_argument("--rounds", type=int, default=2)
    args = p.parse_args()
    for _ in range(args.rounds):
        for days in args.days:
            for fork in (True, False):
                r = run(days, args.episodes, fork)
                line = " ".join(f"{k} {v:.1f}" if isinstance(v, float) else f"{k} {v}" for k, v in r.items())
                print(line, flush=True)


if __name__ == "__main__":
    main()
