"""`parallel-eplus bench --planner RUN`: the planner's milliseconds per decision beside the policy network's.

One building, one core: each controller acts in closed loop on a real episode of the run's first training weather
(the observations EnergyPlus gives under its own actions), and each decision is timed alone, in wall and in the
thread's CPU seconds (a busy machine inflates the first; the second is what the decision itself costs). The
policy is the run's distilled network as training's rollouts run it (numpy). With `served`, the planner is also
exported, served (`parallel-eplus serve`, its own process) and run in closed loop through `evaluate
--controller-url`'s client, as an integrator sees it: each POST /act's round trip (p50, p99) and the server
process's CPU per decision, with the machine's load average while it ran (the machine's other work inflates the
wall times, hardly the CPU).
"""

from __future__ import annotations

import logging
import os
import socket
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from parallel_eplus.engine.config import SimulationConfig
from parallel_eplus.envs.vector_env import EnergyPlusVectorEnv

log = logging.getLogger(__name__)


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


def _process_cpu_s(pid: int) -> float | None:
    """A process's user + system CPU seconds so far (Linux's /proc; None elsewhere)."""
    try:
        fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    except OSError:
        return None
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def served(source: Path, sim: SimulationConfig, options: str | None = None) -> dict:
    """The planner at `source` exported, served over loopback and run in closed loop through evaluate's client on
    `sim`'s episode: POST /act round trips (p50, p99, mean ms), the server's CPU ms per decision, the load average
    (1 minute) before and after, and how many answers fell back."""
    from parallel_eplus.evaluation.http_controller import HttpController

    with tempfile.TemporaryDirectory(prefix="parallel-eplus-served-") as tmp:
        folder = Path(tmp) / "served"
        command = [sys.executable, "-m", "parallel_eplus.cli", "export", str(source.parent), "-o", str(folder),
                   "--record-days", "1", "--quiet", *(["--planner-options", options] if options else [])]  # fmt: skip
        done = subprocess.run(command, capture_output=True, text=True)  # its own command: bench imports no deploy
        if done.returncode:
            raise RuntimeError(f"export failed ({done.returncode}): {done.stderr.strip()[-2000:]}")
        with socket.socket() as s:
            s.bind(("127.0.0.1", 0))
            port = s.getsockname()[1]
        server = subprocess.Popen([sys.executable, "-m", "parallel_eplus.cli", "serve", str(folder), "--port",
                                   str(port)], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)  # fmt: skip
        try:
            deadline = time.monotonic() + 120
            while True:  # until it answers /contract
                try:
                    client = HttpController(f"http://127.0.0.1:{port}")
                    break
                except ValueError:
                    if server.poll() is not None or time.monotonic() > deadline:
                        raise RuntimeError(f"the served planner did not start (exit {server.poll()})") from None
                    time.sleep(0.5)
            load_before, cpu_before = os.getloadavg()[0], _process_cpu_s(server.pid)
            episode = _timed_episode(lambda obs, infos: client(obs[0], infos[0])[None], sim)
            cpu_after, load_after = _process_cpu_s(server.pid), os.getloadavg()[0]
            latency = client.latency()
            client.close()
        finally:
            server.terminate()
            server.wait(timeout=30)
    cpu = None if cpu_before is None or cpu_after is None else 1000 * (cpu_after - cpu_before) / latency["requests"]
    return {"requests": latency["requests"], "round_trip_ms": {k: latency[k] for k in ("p50", "p99", "mean")},
            "server_cpu_ms_per_decision": cpu, "client_cpu_ms": episode["cpu_ms"],
            "load_average": [round(load_before, 2), round(load_after, 2)], "fallbacks": client.fallbacks}  # fmt: skip


def decisions(run: Path, days: int = 2, repeats: int = 3, options: str | None = None, serve: bool = False) -> dict:
    """The planner's and the policy's time per decision, median over `repeats` episodes of `days` each; with
    `serve`, also the planner served in closed loop (`served`), one episode."""
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
    load = [round(os.getloadavg()[0], 2)]  # the machine's other work: it inflates wall times, hardly the CPU
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
    out["load_average"] = [*load, round(os.getloadavg()[0], 2)]  # 1 minute, before and after the episodes
    if serve:
        out["served"] = served(source, sim, options)
    return out


def format_decisions(r: dict) -> str:
    rows = [(f"planner ({r['settings']['candidates']} x {r['settings']['iterations']}, shrink "
             f"{r['settings']['shrink']:g})", r["planner"])]  # fmt: skip
    if "policy" in r:
        rows.append(("policy network (distilled, numpy)", r["policy"]))
    load = "" if "load_average" not in r else f", load average {r['load_average'][0]:.1f}-{r['load_average'][1]:.1f}"
    lines = [f"{r['building']}, {r['weather']}: ms per decision, one building on one core (median over episodes{load})"]
    for label, m in rows:
        lines.append(f"  {label:<38} cpu {m['cpu_ms']['median']:7.3f} (p99 {m['cpu_ms']['p99']:7.3f})   "
                     f"wall {m['wall_ms']['median']:7.3f} (p99 {m['wall_ms']['p99']:7.3f})")  # fmt: skip
    if "served" in r:
        s = r["served"]
        cpu = s["server_cpu_ms_per_decision"]
        lines.append(f"  {'served, POST /act round trip':<38} cpu {'-' if cpu is None else f'{cpu:7.3f}':>7} (the "
                     f"server's per decision)   p50 {s['round_trip_ms']['p50']:7.3f}, p99 "
                     f"{s['round_trip_ms']['p99']:7.3f} over {s['requests']} requests at load "
                     f"{s['load_average'][0]:.1f}-{s['load_average'][1]:.1f}; {s['fallbacks']} fell back")  # fmt: skip
    return "\n".join(lines)
