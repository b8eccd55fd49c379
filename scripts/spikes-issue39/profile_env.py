"""Profile ten consecutive 1-day episodes in one env (issue 39, part 1): cProfile on both sides and a timeline.

The EnergyPlus-side long-lived processes run under cProfile (WarmProcess.start patched here only), each dumping
its profile when its stdin closes. The env side runs under cProfile too.

    python scripts/spikes-issue39/profile_env.py --out /tmp/prof39
"""

from __future__ import annotations

import argparse
import cProfile
import pstats
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from parallel_eplus.engine import warm_process
from parallel_eplus.envs.env import EnergyPlusEnv

WRAP = """
import cProfile, sys, os
sys.argv = ['eplus_callback', '--serve', '--pipes', sys.argv[2]]
out = sys.argv_out if False else None
from parallel_eplus.engine.eplus_callback import main
from parallel_eplus.engine.warm_process import serve
p = cProfile.Profile()
p.enable()
try:
    serve(main)
finally:
    p.disable()
    p.dump_stats(os.path.join(OUT, f"eplus-{os.getpid()}.prof"))
"""


def patch(out: Path) -> None:
    def start(self, pipe_dir):
        code = f"OUT = {str(out)!r}\n" + WRAP
        self.proc = subprocess.Popen(
            [sys.executable, "-c", code, "x", str(pipe_dir)],
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            stderr=subprocess.DEVNULL,
            start_new_session=True,
        )
        import os

        os.set_blocking(self.proc.stdout.fileno(), False)

    warm_process.WarmProcess.start = start


def main() -> None:
    p = argparse.ArgumentParser()
    p.add_argument("--out", type=Path, default=Path("/tmp/prof39"))
    p.add_argument("--episodes", type=int, default=10)
    p.add_argument("--days", type=int, default=1)
    p.add_argument("--eplus", action="store_true", help="profile the EnergyPlus side too")
    args = p.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    if args.eplus:
        patch(args.out)
    prof = cProfile.Profile()
    t0 = time.perf_counter()
    prof.enable()
    env = EnergyPlusEnv(
        weather="CA", run_days=args.days, output_dir=args.out / "eps", keep_episodes=0, energyplus_csv=False
    )
    a = np.zeros(env.action_space.shape, dtype=np.float32)
    marks = []
    try:
        for _ in range(args.episodes):
            t = time.perf_counter()
            env.reset()
            r = time.perf_counter()
            n = 0
            terminated = False
            while not terminated:
                _, _, terminated, _, _ = env.step(a)
                n += 1
            marks.append((t - t0, r - t, time.perf_counter() - r, n))
    finally:
        env.close()
    prof.disable()
    print(f"wall {time.perf_counter() - t0:.3f} s")
    for m in marks:
        print(f"at {m[0]:.3f} reset {m[1] * 1e3:.1f} ms steps {m[2] * 1e3:.1f} ms ({m[3]})")
    prof.dump_stats(args.out / "env.prof")
    pstats.Stats(prof).sort_stats("cumulative").print_stats(45)


if __name__ == "__main__":
    main()
