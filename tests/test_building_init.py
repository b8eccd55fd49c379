"""`building init`: a starter spec from a model, written from EnergyPlus's own listing, that load_spec accepts."""

from __future__ import annotations

import re
import shutil
from pathlib import Path

import pytest
from pyenergyplus import dataset

from parallel_eplus.buildings import resources
from parallel_eplus.buildings.init import init_spec
from parallel_eplus.buildings.spec import load_spec
from parallel_eplus.buildings.survey import survey
from parallel_eplus.cli import main

PROTOTYPE = Path(dataset.modeldir) / "ASHRAE901_OfficeSmall_STD2019_Denver.idf"


def uncomment_actions(text: str, pattern: str) -> str:
    """What a user does next: uncomment the candidate blocks whose comment line matches `pattern`."""
    blocks = text.split("\n\n")
    for i, block in enumerate(blocks):
        lines = block.splitlines()
        if len(lines) > 1 and lines[1] == "# [[actions]]" and re.search(pattern, lines[0]):
            blocks[i] = "\n".join([lines[0]] + [ln.removeprefix("# ") for ln in lines[1:]])
    return "\n\n".join(blocks)


@pytest.mark.slow
def test_init_two_zone_data_center(tmp_path):
    idf = tmp_path / "dc.idf"
    shutil.copy(resources.model_file("2ZoneDataCenterHVAC_wEconomizer.idf"), idf)
    out, summary = init_spec(idf)
    assert out == tmp_path / "dc.toml"
    spec = load_spec(out)
    assert spec.idf == idf and spec.actions == ()
    assert spec.weathers == {"CA": resources.weather_file("USA_CA_San.Francisco.Intl.AP.724940_TMY3.epw")}
    names = [o.name for o in spec.observations]
    assert names[:3] == ["outdoor_temp_c", "west_zone_temp_c", "east_zone_temp_c"]
    assert spec.reward.temperatures == ("west_zone_temp_c", "east_zone_temp_c") and spec.reward.power == "power_w"
    assert any("Fan / Fan Air Mass Flow Rate" in line for line in summary)
    # The paper's actuators are among the candidates, named as the IDF names them; uncommented they load.
    text = out.read_text()
    assert 'key = "West Air Loop Outlet Node"' in text and 'key = "West Zone Supply Fan"' in text
    out.write_text(uncomment_actions(text, r"^# (node West Air Loop Outlet Node|fan West Zone Supply Fan)"))
    actions = load_spec(out).actions
    assert [a.name for a in actions] == ["west_air_loop_outlet_node_setpoint_c", "west_zone_supply_fan_kg_s"]
    assert all(a.low < a.initial <= a.high for a in actions)
    with pytest.raises(ValueError, match="exists"):
        init_spec(idf)  # never overwrites a spec


@pytest.mark.slow
def test_init_prototype_from_the_energyplus_wheel(tmp_path, capsys):
    out = tmp_path / "office.toml"
    weather = resources.weather_file("USA_CO_Golden-NREL.724666_TMY3.epw")
    assert main(["building", "init", str(PROTOTYPE), "--weather", str(weather), "-o", str(out)]) == 0
    assert f"written: {out}" in capsys.readouterr().out
    text = out.read_text()
    spec = load_spec(out)
    assert spec.idf == PROTOTYPE and spec.weathers == {"CO": weather}
    zones = [t.removesuffix("_temp_c") for t in spec.reward.temperatures]
    assert len(zones) == 5 and all(z.startswith(("core_zn", "perimeter_zn")) for z in zones)
    out.write_text(uncomment_actions(text, r"^# zone .* cooling( \(|$)"))
    actions = load_spec(out).actions
    assert [a.actuators[0].control for a in actions] == ["Cooling Setpoint"] * 5
    out.write_text(uncomment_actions(text, r"^# all 5 thermostats' cooling"))
    (together,) = load_spec(out).actions
    assert together.name == "cooling_setpoint_c" and len(together.actuators) == 5
    assert "Air Node" not in text  # zone air nodes' setpoints are the thermostat's, not candidates
    # Every candidate names an actuator EnergyPlus listed for this model.
    listed = {(r[1], r[2], r[3].upper()) for r in survey(PROTOTYPE, weather, days=0).rows if r[0] == "Actuator"}
    for a in actions:
        assert (a.actuators[0].component, a.actuators[0].control, a.actuators[0].key.upper()) in listed


def test_init_bad_model_fails_with_a_message(tmp_path):
    with pytest.raises(FileNotFoundError, match="model file not found"):
        init_spec(tmp_path / "missing.idf")
    broken = tmp_path / "broken.idf"
    broken.write_text("Version,25.2;\nZone,;\n")
    with pytest.raises(ValueError, match="stopped before its first timestep"):
        init_spec(broken)
    assert not (tmp_path / "broken.toml").exists()
