"""The oracle (issue 89): branches of a running episode (engine/eplus_side/branch.py, engine/episodes/branch.py) and
`evaluate --oracle` (learning/oracle/) on real EnergyPlus: a branch equals the episode it was forked from, a failed
one leaves nothing, and the oracle's plan is no worse than the building's own controls on its own cost."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pandas as pd

from parallel_eplus.buildings.building import load_building
from parallel_eplus.buildings.scoring.reward import RewardConfig
from parallel_eplus.engine.actions import scale_action
from parallel_eplus.engine.config import SimulationConfig
from parallel_eplus.engine.episodes.branch import Branches, frame_width
from parallel_eplus.engine.simulation import Simulation
from parallel_eplus.evaluation.controllers import BASELINE_LABEL, Controller
from parallel_eplus.evaluation.sweep import run_sweep
from parallel_eplus.learning.oracle.controller import oracle_controller
from parallel_eplus.learning.oracle.search import PlanCost
from parallel_eplus.learning.oracle.settings import OracleSettings

from .conftest import our_processes


def _children(pid: int) -> dict[int, str]:
    """The live (not yet reaped) children of `pid`, with their command lines."""
    found = {}
    for proc in Path("/proc").iterdir():
        if proc.name.isdigit():
            try:
                stat = (proc / "stat").read_text().rsplit(")", 1)[1].split()
                command = (proc / "cmdline").read_bytes().replace(b"\0", b" ").decode(errors="replace").strip()
            except OSError:
                continue
            if int(stat[1]) == pid and stat[0] != "Z":
                found[int(proc.name)] = command
    return found


def test_a_branch_is_the_episode_and_a_failed_one_leaves_nothing(tmp_path):
    cfg = SimulationConfig(weather="CA", run_days=1, branching=True, native_bridge=False, output_dir=str(tmp_path))
    sim = Simulation(cfg)
    try:
        sim.start()
        for _ in range(4):
            sim.send(np.zeros(len(sim.low)))
            sim.receive()
        same = np.tile(scale_action(np.zeros(len(sim.low)), sim.low, sim.high, sim.action_names), (16, 1))
        other = np.tile(scale_action(np.full(len(sim.low), 0.5), sim.low, sim.high, sim.action_names), (16, 1))
        broken = np.zeros((16, len(sim.low) + 3))  # actions of the wrong width: the fork's EnergyPlus fails
        branches = Branches(sim.process.pipes.dir, frame_width(len(sim.sensor_names)), sim.running)
        scratch = branches.scratch
        try:
            played = branches.run([same, broken, other])
        finally:
            branches.close()
        assert played[1] is None and branches.failed == 1
        assert not (sim.episode_dir / "eplusout.end").exists()  # a failed branch wrote no end of run into the episode
        assert not scratch.exists() and not _children(sim.proc.pid)
        main = []
        for _ in range(16):
            sim.send(np.zeros(len(sim.low)))
            _, _, _, info = sim.receive()
            main.append([info[n] for n in sim.sensor_names])
        assert np.array_equal(played[0][:, 4:], np.array(main))  # bit for bit: the same state, the same steps
        assert not np.array_equal(played[2][:, 4:], np.array(main))
    finally:
        sim.close()
    assert not our_processes()


def _plan_cost(episode_dir: str, settings: OracleSettings) -> float:
    """The oracle's cost of an episode's steps from its second hour: its first starts where the agent model's warm-up
    under its initial action left the zones (half a kelvin below the band), the own controls' where theirs did."""
    steps = pd.read_parquet(Path(episode_dir) / "steps.parquet").iloc[4:]
    infos = [dict(row) for row in steps.to_dict("records")]
    for info in infos:
        info["time"] = pd.Timestamp(info["time"]).to_pydatetime()
    return PlanCost(load_building(None).comfort, settings, RewardConfig().power_weight)(infos)


def test_the_oracle_plans_no_worse_than_the_own_controls(tmp_path):
    options = "horizon_h=2,candidates=10"
    before = _children(os.getpid())  # an xdist worker may hold other tests' children (a Ray node): not this test's
    oracle = oracle_controller(options)
    df = run_sweep([Controller(BASELINE_LABEL, "baseline"), oracle], ["CA"], 1, 1, tmp_path, progress=False)
    assert not df.attrs["failures"] and len(df) == 2
    rows = {r["controller"]: r for r in df.to_dict("records")}
    settings = OracleSettings.from_text(options)
    own, planned = (_plan_cost(rows[label]["episode_dir"], settings) for label in (BASELINE_LABEL, "Oracle"))
    assert planned <= own, f"the oracle's plan costs {planned:.1f}, the own controls' {own:.1f}"
    stats = Path(rows["Oracle"]["episode_dir"]) / "oracle.json"
    assert stats.is_file() and '"decisions": 24' in stats.read_text()
    left = {pid: command for pid, command in _children(os.getpid()).items() if pid not in before}
    assert not our_processes() and not left, left
