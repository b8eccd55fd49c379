"""Where the microseconds of one control step go: EnergyPlus alone, then the same days through our env, timed
phase by phase on both sides of the pipes (docs/speed.md quotes its output).

    .venv/bin/python studies/step-cost/profile_step.py --days 30

- raw: EnergyPlus alone (the C callbacks armed, no pipes) under the env's constant action: its stepping time
  per step is the physics, the floor;
- env: the same days through `Simulation`, each step split at the points below with `perf_counter_ns`
  (a few tens of ns each); EnergyPlus's C side reports how long it waited for each action, from before it
  wrote the observation to having the action (`waited_s` in the episode's energyplus.log);
- EnergyPlus reads each action where it applies it (bridge.py): from writing an observation to needing the
  action it computes the next timestep's start (`ahead_s`), then waits at its actuators for whatever of the
  env's turnaround and the two pipe crossings that work did not cover (`waited_s`).
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import tempfile
import time
from pathlib import Path

import numpy as np

from parallel_eplus.bench.config import BenchConfig
from parallel_eplus.bench.raw import _bench_jobs, _raw_runs
from parallel_eplus.engine.config import SimulationConfig
from parallel_eplus.engine.episode import bridge_counters
from parallel_eplus.engine.simulation import Simulation

PHASES = ("send", "wait", "observation", "reward")  # send: check, scale, encode, write; reward: and the record


def _raw(days: int, workdir: Path) -> dict:
    """EnergyPlus alone, as `bench` runs it: wall seconds, and the stepping time from its first step on."""
    cfg = BenchConfig(raw_days=days)
    constant = np.full((days * 96, 1, 4), cfg.action)
    wall, [stepping] = _raw_runs(_bench_jobs(cfg, workdir, constant, energyplus_csv=False), workdir)
    return {"wall_s": wall, "stepping_s": stepping}


def _env(days: int, workdir: Path) -> dict:
    """`Simulation.send` then `Simulation.receive`, as `EnergyPlusEnv.step` calls them, with clock marks after
    the send, the frame's arrival (`_recv`) and the observation (`_observation`): the real methods, wrapped."""
    sim = Simulation(SimulationConfig(run_days=days, output_dir=str(workdir), energyplus_csv=False))
    clock = time.perf_counter_ns
    action = np.zeros(4, dtype=np.float32)
    marks = np.zeros((sim.steps_per_episode, len(PHASES) + 1), dtype=np.int64)
    k = 0

    def marked(method, slot: int):
        def call(*args):
            out = method(*args)
            marks[k, slot] = clock()
            return out

        return call

    sim._recv, sim._observation = marked(sim._recv, 2), marked(sim._observation, 3)
    try:
        t_start = time.perf_counter()
        sim.start()
        t_first = time.perf_counter()
        for k in range(sim.steps_per_episode):
            m = marks[k]
            m[0] = clock()
            sim.send(action)
            m[1] = clock()
            terminated = sim.receive()[2]
            m[4] = clock()
            if terminated:
                t_last = m[3] / 1e9  # its receive then writes the records and waits for EnergyPlus's exit
        t_end = time.perf_counter()
        counters = bridge_counters(sim.episode_dir)
    finally:
        sim.close()
    d = np.diff(marks[:-1], axis=1) / 1e3  # µs per phase (the last step's receive also finishes the episode)
    medians, means = np.median(d, axis=0).round(2).tolist(), d.mean(axis=0).round(2).tolist()
    return {
        "wall_s": t_end - t_start, "first_obs_s": t_first - t_start, "stepping_s": t_last - t_first,
        "finish_s": t_end - t_last, "phases_median_us": dict(zip(PHASES, medians, strict=True)),
        "phases_mean_us": dict(zip(PHASES, means, strict=True)), "counters": counters, "steps": len(marks),
    }  # fmt: skip


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--days", type=int, default=30)
    p.add_argument("--pairs", type=int, default=3, help="raw, env pairs, alternated; medians are printed")
    p.add_argument("--json", type=Path, help="also write every run's figures here")
    args = p.parse_args()
    runs = []
    with tempfile.TemporaryDirectory(prefix="parallel-eplus-profile-") as tmp:
        for i in range(args.pairs):
            runs.append({"raw": _raw(args.days, Path(tmp) / f"raw{i}"), "env": _env(args.days, Path(tmp) / f"env{i}")})
    if args.json:
        args.json.write_text(json.dumps(runs, indent=2))
    med = statistics.median
    steps = runs[0]["env"]["steps"]
    print(f"{args.days} days, {steps} steps, median of {args.pairs} alternated pairs (µs per step)")
    for phase in PHASES:
        print(f"  env {phase:12s} {med(r['env']['phases_median_us'][phase] for r in runs):8.2f} (median step)"
              f" {med(r['env']['phases_mean_us'][phase] for r in runs):8.2f} (mean)")  # fmt: skip
    waited, ahead = (
        med(r["env"]["counters"].get(k, float("nan")) / steps * 1e6 for r in runs) for k in ("waited_s", "ahead_s")
    )
    turnaround = med(sum(r["env"]["phases_mean_us"][p] for p in PHASES if p != "wait") for r in runs)
    print(f"  the env's own turnaround {turnaround:8.2f}; EnergyPlus meanwhile computed the next timestep's start"
          f" for {ahead:8.2f}, then waited at its actuators {waited:8.2f}")  # fmt: skip
    physics = med(r["raw"]["stepping_s"] for r in runs) / steps * 1e6
    stepping = med(r["env"]["stepping_s"] for r in runs) / steps * 1e6
    print(f"  raw EnergyPlus stepping {physics:8.2f}; the env's stepping {stepping:8.2f}")
    raw = med(r["raw"]["wall_s"] for r in runs)
    env = med(r["env"]["wall_s"] for r in runs)
    ratio = med(r["env"]["wall_s"] / r["raw"]["wall_s"] for r in runs)
    first, finish = (med(r["env"][k] for r in runs) for k in ("first_obs_s", "finish_s"))
    print(f"  raw {raw:.2f} s, env {env:.2f} s (first observation {first:.2f} s, finish {finish:.2f} s);"
          f" env/raw {ratio:.3f}; overhead {(env - raw) / steps * 1e6:.1f} µs a step")  # fmt: skip
    print(f"  load average {os.getloadavg()[0]:.2f}")


if __name__ == "__main__":
    main()
