"""A timeline of ten consecutive 1-day episodes in one env, both sides (issue 39, part 1).

Timestamps (CLOCK_MONOTONIC, shared by all processes) from the env side (reset, first observation, first action,
last observation, finish) and the EnergyPlus side (request read, new_state, run start, observation 0 written,
last step, run_energyplus returned, delete_state, done written). Patches only this script's processes.

    python scripts/spikes-issue39/timeline.py --episodes 10 --days 1
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from parallel_eplus.engine import simulation, warm_process
from parallel_eplus.envs.env import EnergyPlusEnv

WRAP = r"""
import json, os, sys, time
LOG = open(os.path.join(OUT, f"ep-{os.getpid()}.jsonl"), "a", buffering=1)
def mark(what, **kw):
    LOG.write(json.dumps({"t": time.monotonic(), "pid": os.getpid(), "what": what, **kw}) + "\n")
mark("proc_start")
from pyenergyplus import state as st, runtime as rt
from parallel_eplus.engine import bridge as br, eplus_callback as ec, warm_process as wp
def wrap(obj, name, label):
    f = getattr(obj, name)
    def g(*a, **k):
        mark(label + "_begin")
        try:
            return f(*a, **k)
        finally:
            mark(label + "_end")
    setattr(obj, name, g)
wrap(st.StateManager, "new_state", "new_state")
wrap(st.StateManager, "delete_state", "delete_state")
wrap(rt.Runtime, "run_energyplus", "run")
wrap(ec, "main", "main")
ex = br.Bridge._exchange
def exchange(self, values):
    if self.step == 0:
        mark("obs0_written")
    return ex(self, values)
br.Bridge._exchange = exchange
ow = os.write
mark("imports_done")
sys.argv = ['x', '--serve']
sys.exit(wp.serve(ec.main))
"""

T: list[dict] = []


def mark(what: str, **kw) -> None:
    T.append({"t": time.monotonic(), "pid": os.getpid(), "what": what, **kw})


def patch(out: Path) -> None:
    def start(self, pipe_dir):
        self.proc = subprocess.Popen(
            [sys.executable, "-c", f"OUT = {str(out)!r}\n" + WRAP],
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            stderr=subprocess.DEVNULL,
            start_new_session=True,
        )
        os.set_blocking(self.proc.stdout.fileno(), False)
        mark("warm_start", child=self.proc.pid)

    warm_process.WarmProcess.start = start
    S = simulation.Simulation
    for name in ("launch", "prepare", "first_observation", "_finish", "_write_records", "close"):
        f = getattr(S, name)

        def g(self, *a, _f=f, _n=name, **k):
            mark(_n + "_begin")
            try:
                return _f(self, *a, **k)
            finally:
                mark(_n + "_end")

        setattr(S, name, g)
    P = simulation.EnergyPlusProcess
    for name in ("finish", "spawn"):
        f = getattr(P, name)

        def h(self, *a, _f=f, _n=name, **k):
            mark(_n + "_begin")
            try:
                return _f(self, *a, **k)
            finally:
                mark(_n + "_end", child=getattr(self.proc, "pid", None))

        setattr(P, name, h)


def main() -> None:
    p = argparse.ArgumentParser()
    p.add_argument("--out", type=Path, default=Path("/tmp/tl39"))
    p.add_argument("--episodes", type=int, default=10)
    p.add_argument("--days", type=int, default=1)
    args = p.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    for f in args.out.glob("ep-*.jsonl"):
        f.unlink()
    patch(args.out)
    t0 = time.monotonic()
    mark("env_init")
    env = EnergyPlusEnv(
        weather="CA", run_days=args.days, output_dir=args.out / "eps", keep_episodes=0, energyplus_csv=False
    )
    a = np.zeros(env.action_space.shape, dtype=np.float32)
    try:
        for k in range(args.episodes):
            mark("reset_begin", k=k)
            env.reset()
            mark("reset_end", k=k)
            terminated = False
            while not terminated:
                _, _, terminated, _, _ = env.step(a)
            mark("episode_end", k=k)
    finally:
        env.close()
    mark("closed")
    rows = list(T)
    for f in args.out.glob("ep-*.jsonl"):
        rows += [json.loads(x) for x in f.read_text().splitlines()]
    rows.sort(key=lambda r: r["t"])
    pids = sorted({r["pid"] for r in rows})
    for r in rows:
        col = pids.index(r["pid"])
        extra = {k: v for k, v in r.items() if k not in ("t", "pid", "what")}
        print(
            f"{(r['t'] - t0) * 1e3:8.1f}  {'    ' * 0}{'env ' if r['pid'] == os.getpid() else f'E{col}  '}"
            f"{'  ' * col}{r['what']} {extra if extra else ''}"
        )
    print(f"wall {(time.monotonic() - t0):.3f} s")


if __name__ == "__main__":
    main()
