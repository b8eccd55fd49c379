"""Node setpoints taken over from the model's own setpoint managers in the prepared copy, and proved to reach their
nodes by `building check` (buildings/idf/takeover.py, reach.py): the DOE medium office from the EnergyPlus wheel, as it
ships, its first air loop's supply-air temperature owned by the agent."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from parallel_eplus.buildings.check import reach
from parallel_eplus.buildings.check.names import check_spec
from parallel_eplus.buildings.idf.prepare import prepare_idf
from parallel_eplus.buildings.resources import weather_file
from parallel_eplus.buildings.spec.load import load_spec

SUPPLY = "VAV_1 Supply Equipment Outlet Node"


def medium_office() -> Path:
    import pyenergyplus.dataset as d

    return Path(d.ref_models["medium_office"])


def action(name: str, node: str, low: float, high: float, initial: float) -> str:
    return f"""
[[actions]]
name = "{name}"
unit = "C"
low = {low}
high = {high}
initial = {initial}
actuators = [{{ component = "System Node Setpoint", control = "Temperature Setpoint", key = "{node}" }}]
"""


def office_spec(tmp_path: Path, actions: str) -> Path:
    text = f"""name = "medium-office"
idf = "{medium_office()}"
[weathers]
CO = "USA_CO_Golden-NREL.724666_TMY3.epw"
[[observations]]
name = "core_mid_temp_c"
variable = "Zone Mean Air Temperature"
key = "Core_mid"
low = -20.0
high = 50.0
[[observations]]
name = "power_w"
variable = "Facility Total Electricity Demand Rate"
key = "Whole Building"
low = 0.0
high = 1e9
{actions}
[reward]
temperatures = ["core_mid_temp_c"]
power = "power_w"
band = [21.0, 24.0]
"""
    path = tmp_path / "office.toml"
    path.write_text(text)
    return path


@pytest.fixture(autouse=True)
def private_cache(tmp_path, monkeypatch):
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))


def test_the_prepared_copy_drops_the_node_from_its_manager_and_keeps_the_followers(tmp_path):
    spec = load_spec(office_spec(tmp_path, action("supply_c", SUPPLY.upper(), 12.0, 18.0, 13.0)))
    from parallel_eplus.buildings.idf.takeover import taken_setpoints

    report = prepare_idf(medium_office(), tmp_path / "model.idf", 1, takeover=taken_setpoints(spec.actions))
    text = (tmp_path / "model.idf").read_text(encoding="latin-1")
    from parallel_eplus.buildings.idf.objects import idf_objects

    managers = {o.fields[0]: o for o in idf_objects(text) if o.kind.lower().startswith("setpointmanager:")}
    assert "VAV_1 SAT setpoint" not in managers  # commented out: the only node it set is the agent's
    assert "! parallel-eplus: removed in this copy" in text
    assert managers["VAV_2 SAT setpoint"].fields[3] == "VAV_2 Supply Equipment Outlet Node"  # another loop's: kept
    followers = [n for n, o in managers.items() if o.kind == "SetpointManager:MixedAir" and o.fields[2] == SUPPLY]
    assert len(followers) == 3  # they follow the agent's node now
    lines = report.lines()
    assert lines[0] == f'SetpointManager:Scheduled "VAV_1 SAT setpoint" removed: the agent sets {SUPPLY}'
    assert sum("kept: it follows" in ln for ln in lines) == 3
    assert "! parallel-eplus" not in medium_office().read_text(encoding="latin-1")  # the user's file is untouched


def test_a_manager_of_several_nodes_keeps_the_others_and_other_setpoints_stay(tmp_path):
    idf = tmp_path / "m.idf"
    idf.write_text("""Version,25.2;
  NodeList, Outlets, Node A, Node B, Node C;
  SetpointManager:Scheduled, Three, Temperature, Sch, Outlets;
  SetpointManager:Scheduled, Two, Temperature, Sch, Node B;
  SetpointManager:Scheduled, Lowest, MinimumTemperature, Sch, Node A;
  SetpointManager:SingleZone:Humidity:Minimum, Dry, Node A, Zone Node;
""")
    out = tmp_path / "out.idf"
    report = prepare_idf(idf, out, 1, takeover=(("NODE A", "temperature"),))
    text = out.read_text()
    assert "Three, Temperature, Sch, Three nodes kept by parallel-eplus;" in text  # a NodeList of what it still sets
    assert "NodeList,\n    Three nodes kept by parallel-eplus,\n    Node B,\n    Node C;" in text
    assert "SetpointManager:Scheduled, Lowest" in text  # the node's minimum temperature setpoint is not the agent's
    assert "SetpointManager:SingleZone:Humidity:Minimum, Dry" in text  # nor its humidity
    assert [(r.name, r.removed) for r in report.replaced] == [("Three", False)]
    report = prepare_idf(idf, out, 1, takeover=(("NODE A", "temperature"), ("NODE B", "temperature")))
    text = out.read_text()
    assert "Three, Temperature, Sch, Node C;" in text  # one node left: named directly
    assert [(r.name, r.removed) for r in report.replaced] == [("Three", False), ("Two", True)]


@pytest.mark.slow
def test_check_proves_the_supply_air_follows_the_action_and_names_a_node_that_does_not(tmp_path, no_leaks, monkeypatch):
    """The air loop's supply node follows the action at both ends of 12-18 C; a VAV box's outlet node, whose
    setpoint no component controls to, fails with the reason; without the takeover the manager's schedule wins."""
    actions = action("supply_c", SUPPLY, 12.0, 18.0, 13.0) + action(
        "box_c", "Core_bottom VAV Box Outlet Node Name", 15.0, 30.0, 20.0
    )
    path = office_spec(tmp_path, actions)
    proofs = []  # what the check's own proof found at each end (its runs are the check's: not run twice)
    prove = reach.prove_reach
    monkeypatch.setattr(reach, "prove_reach", lambda spec, epw: proofs.append(prove(spec, epw)) or proofs[-1])
    result = check_spec(path, "CO", use_cache=False)
    assert len(result.problems) == 2, result.problems
    assert all('"box_c"' in p and "but no component controls to it there" in p for p in result.problems)
    spec = load_spec(path)
    epw = weather_file("USA_CO_Golden-NREL.724666_TMY3.epw")
    assert len(proofs) == 1
    problems, _, reaches = proofs[0]
    assert list(problems) == list(result.problems)  # the check's problems are its proof's
    supply = {r.end: r for r in reaches if r.action == "supply_c"}
    assert supply["low"].ok and supply["high"].ok and supply["low"].samples > 50
    assert abs(supply["low"].mean_c - 12.0) < 0.1 and abs(supply["high"].mean_c - 18.0) < 0.1

    request = reach._request(spec) | {"takeover": []}  # the model's own manager left in: it wins
    (tmp_path / "r").mkdir()
    (tmp_path / "r" / "request.json").write_text(json.dumps(request))
    cmd = [sys.executable, "-m", "parallel_eplus.buildings.check.reach",
           "--probe", str(tmp_path / "r" / "request.json"),
           "--weather", str(epw)]  # fmt: skip
    subprocess.run(cmd, cwd=tmp_path / "r", check=True, capture_output=True, timeout=reach.TIMEOUT_S)
    samples = json.loads((tmp_path / "r" / "samples.json").read_text())
    problems, _, reaches = reach.judge(spec, reach.node_actions(spec)[:1], samples)
    low = next(r for r in reaches if r.end == "low")
    assert problems and not low.ok and abs(low.mean_c - 12.8) < 0.1  # the schedule's 12.8 C, not the action's 12


def _relinquished_day(tmp: Path, supply_air: float) -> tuple[pd.DataFrame, pd.DataFrame]:
    """office-medium for two January days under `relinquish`, every thermostat released and the three loops' supply
    air commanded (NaN: released too): its steps, and the cooling coils' setpoints (the MixedAir managers' nodes)."""
    from parallel_eplus.engine.config import SimulationConfig
    from parallel_eplus.engine.simulation import Simulation

    coil = "VAV_1_COOLC-VAV_1_HEATCNODE"
    sim = Simulation(SimulationConfig(building="office-medium", weather="CO", run_days=2, output_dir=str(tmp),
                                      relinquish=True, energyplus_csv=True,
                                      extra_outputs=((coil, "System Node Setpoint Temperature"),)))  # fmt: skip
    low, high = 12.0, 18.0  # office-medium's supply_air_c
    action = np.array([np.nan, np.nan, np.nan if np.isnan(supply_air) else 2 * (supply_air - low) / (high - low) - 1])
    try:
        sim.launch()
        sim.first_observation()
        while True:
            sim.send(action)
            _, _, terminated, info = sim.receive()
            if terminated:
                break
    finally:
        sim.close()
    folder = Path(info["episode_dir"])
    csv = pd.read_csv(folder / "eplusout.csv")
    return pd.read_parquet(folder / "steps.parquet"), csv[[c for c in csv.columns if coil in c.upper()]].dropna()


@pytest.mark.slow
def test_a_relinquished_supply_air_is_the_buildings_own_and_a_commanded_one_reaches_the_coils(tmp_path, no_leaks):
    """`relinquish` (the BACnet device, `--rbc` rules that release actions): the copy drops the node's scheduled
    manager, so a commanded supply air is the one its MixedAir managers follow; released, the bridge writes the
    manager's schedule and the run is the building's own controls. Kept, the manager wrote 12.8 C before each apply
    point and the coils never saw a commanded 18."""
    from parallel_eplus.evaluation.controllers import BASELINE_LABEL, Controller
    from parallel_eplus.evaluation.sweep import run_sweep

    df = run_sweep([Controller(BASELINE_LABEL, "baseline")], ["CO"], 2, 1, tmp_path / "own", progress=False,
                   building="office-medium")  # fmt: skip
    own = pd.read_parquet(Path(df["episode_dir"][0]) / "steps.parquet")
    released, released_coil = _relinquished_day(tmp_path / "released", np.nan)
    for signal in ("hvac_power_w", "hvac_naturalgas_w", "core_mid_temp_c"):  # step by step, warm-up included
        np.testing.assert_allclose(released[signal], own[signal], rtol=1e-6, atol=1e-6)
    assert np.allclose(released_coil.to_numpy(), 12.8, atol=1.0)  # 12.8 minus the fan's heat
    commanded, commanded_coil = _relinquished_day(tmp_path / "commanded", 18.0)
    assert (commanded["supply_air_c"] == 18.0).all()
    assert commanded_coil.to_numpy().mean() > released_coil.to_numpy().mean() + 4  # 18 minus the fan's heat
