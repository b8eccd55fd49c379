"""An exported planner as the BACnet supervisor's controller (deploy/bacnet/planner.py), in lockstep with a
simulated device."""

from __future__ import annotations

import datetime as dt
import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from parallel_eplus.deploy.export.policy import export

from .bacnet_loop import Loop

pytest.importorskip("BAC0")

ROOT = Path(__file__).resolve().parents[1]
PLANNER = ROOT / "results/model-based/datacenter-2zone/runs/datacenter-2zone-mpc-seed0"  # committed


@pytest.fixture
def loop(tmp_path, no_leaks):
    lp = Loop(tmp_path)
    try:
        yield lp
    finally:
        lp.close()


def in_process_planner(controller: Path, tmp: Path) -> pd.DataFrame:
    """The exported planner acting in process on the device's simulation, each step's request as the supervisor
    makes it (its state carried from answer to answer), its setpoints as a BACnet REAL carries them."""
    from parallel_eplus.deploy.bacnet.planner import PlannerSteps
    from parallel_eplus.deploy.serve.contract import Contract
    from parallel_eplus.engine.config import SimulationConfig
    from parallel_eplus.engine.simulation import Simulation

    contract = Contract.read(controller)
    planner = PlannerSteps(controller, contract)
    low, high = (np.array([o[k] for o in contract.outputs]) for k in ("low", "high"))
    names = [s["name"] for s in contract.sensors]
    sim = Simulation(SimulationConfig(weather="CA", run_days=1, output_dir=str(tmp), relinquish=True,
                                      native_bridge=False))  # fmt: skip
    try:
        sim.launch()
        obs, info = sim.first_observation()
        for k in range(10**6):
            sensors = dict(zip(names, obs[: len(names)].tolist(), strict=True))
            row = planner.answer(sensors, {}, info["time"].isoformat(), k)
            action = np.full(len(low), np.nan) if row is None else row.astype(np.float32).astype(np.float64)
            sim.send(2 * (action - low) / (high - low) - 1)
            obs, _, terminated, info = sim.receive()
            if terminated:
                return pd.read_parquet(Path(info["episode_dir"]) / "steps.parquet")
    finally:
        sim.close()


@pytest.mark.slow
def test_a_planner_supervises_a_day_over_bacnet_as_it_answers_in_process(loop, tmp_path):
    """An exported planner (`--persistence`: no forecast comes over BACnet) in lockstep: every reading and setpoint
    of the day equal to its answers in process; one that needs a forecast is refused, naming the export's option."""
    from parallel_eplus.deploy.bacnet.supervisor import Supervisor, SupervisorConfig

    planner = tmp_path / "planner"
    export(PLANNER, planner, record_days=1, persistence=True)
    loop.device()
    loop.supervisor(planner)
    assert loop.wait("supervisor") == 0, loop.log("supervisor")
    assert loop.wait("device") == 0, loop.log("device")
    over_bacnet = loop.steps()
    assert len(over_bacnet) == 96 and "acted on 96 steps (0 fallbacks)" in loop.log("supervisor")
    pd.testing.assert_frame_equal(in_process_planner(planner, tmp_path / "reference"), over_bacnet, check_exact=True)

    from parallel_eplus.deploy.bacnet.planner import PlannerSteps
    from parallel_eplus.deploy.serve.contract import Contract

    steps = PlannerSteps(planner, Contract.read(planner))  # a reading it cannot take: the building's own controls
    assert steps.answer({"outdoor_temp_c": 12.0}, {}, "2017-07-01T14:00:00", 5) is None
    then = steps.runtime.own(dt.datetime(2017, 7, 1, 14))  # what the own controls set at that date and time
    assert list(steps.last.values()) == pytest.approx(then.tolist())  # then in force: theirs
    contract = json.loads((planner / "controller.json").read_text())
    contract["forecast"]["missing"] = "refuse"
    (planner / "controller.json").write_text(json.dumps(contract))
    with pytest.raises(ValueError, match="--persistence"):
        Supervisor(SupervisorConfig(planner, loop.address, loop.map))
