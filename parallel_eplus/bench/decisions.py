"""`parallel-eplus bench --planner RUN`: the planner's milliseconds per decision beside the policy network's.

One building, one core: each controller acts in closed loop on a real episode of the run's first training weather
(the observations EnergyPlus gives under its own actions), and each decision is timed alone, in wall and in the
thread's CPU seconds (a busy machine inflates the first; the second is what the decision itself costs). The
policy is the run's distilled network as training's rollouts run it (numpy); the served planner adds one HTTP
round trip on top of the planner's own time (studies/deploy/deploy_latency.py measures that).
"""

from __future__ import annotations

import statistics
import time
from pathlib import Path

import numpy as np

from parallel_eplus.engine.config import SimulationConfig
from parallel_eplus.envs.vector_env import EnergyPlusVectorEnv


def _timed_episode(act, sim: SimulationConfig) -> dict:
    venv = EnergyPlusVectorEnv(sim, [[sim.weather]])
    wall, cpu = [], []
    try:
        infos = venv.start_all([0])
        obs = venv.observations()
        done = False
        while not done:
            w0, c0 = time.perf_counter(), time.thread_time()
            action = act(obs, infos)
            cpu.append(time.thread_time() - c0)
            wall.append(time.perf_counter() - w0)
            obs, _, dones, _, infos = venv.step_lists(action)
            done = bool(dones[0])
    finally:
        venv.close()
    return {"decisions": len(wall), "wall_ms": _summary(wall), "cpu_ms": _summary(cpu)}


def _summary(seconds: list[float]) -> dict:
    ms = np.array(seconds) * 1000
    return {"median": float(np.median(ms)), "p99": float(np.percentile(ms, 99)), "mean": float(ms.mean())}


def decisions(run: Path, days: int = 2, repeats: int = 3, options: str | None = None) -> dict:
    """The planner's and the policy's time per decision, median over `repeats` episodes of `days` each."""
    import json

    import torch as th

    from parallel_eplus.buildings.resources import saved_building
    from parallel_eplus.learning.model_based.control.mpc import MPC
    from parallel_eplus.learning.model_based.control.saved_planner import PlannerOptions, planner_source
    from parallel_eplus.runs.policy_files import load_policy

    th.set_num_threads(1)
    source = planner_source(run)
    if source is None:
        raise FileNotFoundError(f"{run}: no planner (a `train --algorithm mpc` run has planner/ or best/planner/)")
    saved = json.loads((source.parent / "config.json").read_text())
    building, weather = saved_building(saved), (saved.get("weathers") or ["CA"])[0]
    out: dict = {"planner": str(source), "building": building or "datacenter-2zone", "weather": weather}
    mpc = PlannerOptions.parse(options, flag="--planner-options").apply(MPC.load(source))
    s = mpc.planner.settings
    out["settings"] = {"candidates": s.candidates, "iterations": s.iterations, "elites": s.elites, "shrink": s.shrink,
                       "horizon": s.horizon}  # fmt: skip
    run_dir = source.parent.parent  # runs/<name>/planner/planner.pt, or runs/<name>/best/planner/planner.pt
    policy_zip = (run_dir.parent if run_dir.name == "best" else run_dir) / "model.zip"  # the distilled policy

    def planner(obs, infos):
        planner.last = mpc.act(obs, infos, planner.last)
        return planner.last

    planner.last = mpc.initial[None].copy()
    # what the run observed (the clock's and the schedule's features, a forecast): its distilled policy needs them
    sim = SimulationConfig(weather=weather, run_days=days, building=building,
                           time_features=bool(saved.get("time_features")),
                           schedule_features=bool(saved.get("schedule_features")),
                           forecast_hours=int(saved.get("forecast_hours", 0)),
                           forecast_error=saved.get("forecast_error"))  # fmt: skip
    runs = {"planner": [], "policy": []}
    act = load_policy(policy_zip) if policy_zip.is_file() else None
    for _ in range(repeats):
        mpc.reset(0)
        planner.last = mpc.initial[None].copy()
        runs["planner"].append(_timed_episode(planner, sim))
        if act is not None:
            runs["policy"].append(_timed_episode(lambda obs, infos: act(obs), sim))
    for name, episodes in runs.items():
        if episodes:
            out[name] = {k: {s: statistics.median(e[k][s] for e in episodes) for s in ("median", "p99", "mean")}
                         for k in ("wall_ms", "cpu_ms")}  # fmt: skip
            out[name]["decisions"] = episodes[0]["decisions"]
    if act is not None:
        out["policy"]["model"] = str(policy_zip)
    return out


def format_decisions(r: dict) -> str:
    rows = [(f"planner ({r['settings']['candidates']} x {r['settings']['iterations']}, shrink "
             f"{r['settings']['shrink']:g})", r["planner"])]  # fmt: skip
    if "policy" in r:
        rows.append(("policy network (distilled, numpy)", r["policy"]))
    lines = [f"{r['building']}, {r['weather']}: ms per decision, one building on one core (median over episodes)"]
    for label, m in rows:
        lines.append(f"  {label:<38} cpu {m['cpu_ms']['median']:7.3f} (p99 {m['cpu_ms']['p99']:7.3f})   "
                     f"wall {m['wall_ms']['median']:7.3f} (p99 {m['wall_ms']['p99']:7.3f})")  # fmt: skip
    return "\n".join(lines)
