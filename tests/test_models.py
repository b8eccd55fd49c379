"""The committed models are the transition script's output and read their fields correctly."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from parallel_eplus.buildings.datacenter import AGENT_IDF, BASELINE_IDF, ROOT

SOURCE = ROOT.parent / "shared" / "reference" / "2ZoneDataCenterHVAC_wEconomizer-baseline-22.2.idf"


@pytest.mark.skipif(not SOURCE.exists(), reason="the authors' reference model is not beside this checkout")
def test_idf_dir_is_up_to_date_with_make_models():
    result = subprocess.run(
        [sys.executable, str(ROOT / "tools" / "make_models.py"), "--check"], capture_output=True, text=True
    )
    assert result.returncode == 0, result.stderr


def active_objects(path: Path, kind: str) -> list[str]:
    text = "\n".join(line.split("!")[0] for line in path.read_text(encoding="latin-1").splitlines())
    return [obj for obj in text.split(";") if obj.strip().lower().startswith(kind.lower() + ",")]


def test_both_zones_use_flow_from_system():
    for path in (BASELINE_IDF, AGENT_IDF):
        ite = active_objects(path, "ElectricEquipment:ITE:AirCooled")
        assert len(ite) == 2
        assert all("FlowFromSystem" in obj for obj in ite)


def test_agent_variant_differs_only_by_the_zone_setpoint_managers():
    assert len(active_objects(BASELINE_IDF, "SetpointManager:SingleZone:Cooling")) == 2
    assert active_objects(AGENT_IDF, "SetpointManager:SingleZone:Cooling") == []
    base = [o for o in active_objects(BASELINE_IDF, "") if "SetpointManager:SingleZone:Cooling" not in o]
    assert base == active_objects(AGENT_IDF, "")


@pytest.mark.slow
def test_baseline_year_runs_without_severe_input_errors(tmp_path):
    """A short baseline run: no Severe at input processing, DX coils read their curves."""
    from parallel_eplus.buildings.idf.prepare import prepare_idf

    idf = tmp_path / "model.idf"
    prepare_idf(BASELINE_IDF, idf, run_days=2)
    epw = ROOT / "weather" / "USA_CA_San.Francisco.Intl.AP.724940_TMY3.epw"
    code = (
        "from pyenergyplus.api import EnergyPlusAPI; import sys;"
        "a = EnergyPlusAPI(); s = a.state_manager.new_state();"
        "a.runtime.set_console_output_status(s, False);"
        f"sys.exit(a.runtime.run_energyplus(s, ['-d', r'{tmp_path}', '-w', r'{epw}', r'{idf}']))"
    )
    assert subprocess.run([sys.executable, "-c", code]).returncode == 0
    err = (tmp_path / "eplusout.err").read_text()
    assert "Completed Successfully" in err
    input_phase = err.split("Beginning Simulation")[0]  # input processing and sizing
    assert "Severe" not in input_phase
    assert "not found Sensible Heat Ratio" not in err
    assert "ZoneAveraged" not in err


@pytest.mark.slow
def test_the_crac_agent_model_starts_on_the_golden_weather(tmp_path, no_leaks):
    """Its design days made EnergyPlus fail at the first step of the CO year (an unset supply node, -289 C)."""
    from parallel_eplus.engine.config import SimulationConfig
    from parallel_eplus.engine.simulation import Simulation

    sim = Simulation(SimulationConfig(weather="CO", building="datacenter-crac", run_days=1, output_dir=str(tmp_path)))
    try:
        sim.launch()
        obs, _ = sim.first_observation()
        for _ in range(10):
            sim.send([0.0, 0.0])  # mid-range supply temperature and fan flow
            obs, _, _, _ = sim.receive()
        assert 10 < obs[1] < 40  # the servers' inlet air, in °C
    finally:
        sim.close()
