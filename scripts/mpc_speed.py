"""Steps/s of the planner against a policy network on the same workers, interleaved (A B A B ...), and the
planner's milliseconds per vector step: docs/model-based.md quotes it.

    .venv/bin/python scripts/mpc_speed.py runs/<mpc run> [--steps 384] [--rounds 3] [--workers 2]

A: the run's planner (one batched plan for every worker per vector step); B: the run's distilled policy (a
32x32 network in numpy, as TRPO's rollouts run it). Both step the same 2-day CA episodes through
`EnergyPlusVectorEnv`, so the ratio is the planner's cost on top of EnergyPlus and the pipes.
"""

from __future__ import annotations

import argparse
import logging
import statistics
import time
from pathlib import Path

import numpy as np
import torch as th

from parallel_eplus.engine.config import SimulationConfig
from parallel_eplus.envs.vector_env import EnergyPlusVectorEnv
from parallel_eplus.learning.model_based.control import MPC
from parallel_eplus.runs.policy_files import load_policy


def steps_per_s(run: Path, planner: bool, steps: int, workers: int) -> tuple[float, float]:
    venv = EnergyPlusVectorEnv(SimulationConfig(weather="CA", run_days=2), [["CA"]] * workers)
    try:
        infos = venv.start_all(range(workers))
        obs = venv.observations()
        mpc = MPC.load(run / "planner" / "planner.pt", workers=workers) if planner else None
        act = None if planner else load_policy(run / "model.zip")
        last = np.tile(mpc.initial, (workers, 1)) if planner else None
        plan_ms, t0 = [], time.perf_counter()
        for _ in range(steps // workers):
            if planner:
                last = mpc.act(obs, infos, last)
                plan_ms.append(mpc.planner.last_ms)
                actions = last
            else:
                actions = act(obs)
            obs, _, _, _, infos = venv.step_lists(actions)
        rate = (steps // workers) * workers / (time.perf_counter() - t0)
        return rate, float(np.median(plan_ms)) if plan_ms else 0.0
    finally:
        venv.close()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("run", type=Path)
    parser.add_argument("--steps", type=int, default=384)
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--workers", type=int, default=2)
    args = parser.parse_args()
    logging.basicConfig(level=logging.WARNING)
    th.set_num_threads(1)
    ratios, planner_rates, policy_rates, ms = [], [], [], []
    for _ in range(args.rounds):
        (a, plan), (b, _) = (
            steps_per_s(args.run, True, args.steps, args.workers),
            steps_per_s(args.run, False, args.steps, args.workers),
        )
        planner_rates.append(a), policy_rates.append(b), ratios.append(a / b), ms.append(plan)
    med = statistics.median
    print(
        f"planner: {med(planner_rates):.1f} steps/s (plan {med(ms):.1f} ms per vector step of {args.workers} workers)"
    )
    print(f"policy:  {med(policy_rates):.1f} steps/s")
    print(f"planner/policy steps/s, paired: median {med(ratios):.3f} (min {min(ratios):.3f}, max {max(ratios):.3f})")


if __name__ == "__main__":
    main()
