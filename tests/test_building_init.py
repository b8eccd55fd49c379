"""`building init`: a starter spec from a model, written from EnergyPlus's own listing, that load_spec accepts."""

from __future__ import annotations

import functools
import re
import shutil
from pathlib import Path

import pytest
from pyenergyplus import dataset

from parallel_eplus.buildings import resources
from parallel_eplus.buildings.spec.load import load_spec
from parallel_eplus.buildings.starter.survey import survey
from parallel_eplus.buildings.starter.write import init_spec
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
def test_init_prototype_from_the_energyplus_wheel(tmp_path, capsys, monkeypatch):
    from parallel_eplus.buildings.starter import write

    surveys = []  # what EnergyPlus listed for this model in init's own survey (kept for the last check)
    monkeypatch.setattr(write, "survey", lambda *a, **kw: surveys.append(survey(*a, **kw)) or surveys[-1])
    out = tmp_path / "office.toml"
    weather = resources.weather_file("USA_CO_Golden-NREL.724666_TMY3.epw")
    assert main(["building", "init", str(PROTOTYPE), "--weather", str(weather), "-o", str(out)]) == 0
    assert f"written: {out}" in capsys.readouterr().out
    text = out.read_text()
    spec = load_spec(out)
    assert spec.idf == PROTOTYPE and spec.weathers == {"CO": weather}
    assert f'idf = "{PROTOTYPE.name}"' in text  # the wheel's model by name: the starter works on any install
    zones = [t.removesuffix("_temp_c") for t in spec.reward.temperatures]
    assert len(zones) == 5 and all(z.startswith(("core_zn", "perimeter_zn")) for z in zones)
    out.write_text(uncomment_actions(text, r"^# zone .* cooling( \(|$)"))
    actions = load_spec(out).actions
    assert [a.actuators[0].control for a in actions] == ["Cooling Setpoint"] * 5
    # One knob per setpoint schedule: four zones follow CLGSETP_SCH_NO_OPTIMUM, one its "_w_SB" variant.
    out.write_text(uncomment_actions(text, r"^# (all \d thermostats'|the one thermostat's) cooling"))
    knobs = {a.name: len(a.actuators) for a in load_spec(out).actions}
    knob = "cooling_setpoint_clgsetp_sch_no_optimum"
    assert knobs == {f"{knob}_c": 4, f"{knob}_w_sb_c": 1}
    assert "Air Node" not in text  # zone air nodes' setpoints are the thermostat's, not candidates
    # The survey's week has working days in it (January 1 is a Sunday and a holiday here): the occupied setpoint
    # and the setback are both seen, and every fan ran.
    assert "cooling setpoints on schedule CLGSETP_SCH_NO_OPTIMUM together (seen 23.9..29.4 C)" in text
    assert text.count("# fan ") == 5 and "at most 0.0 kg/s" not in text
    # Its five packaged units each follow their own zone (SetpointManager:SingleZone:Reheat): no shared supply-air
    # knob, which would end every zone's feedback; each node is still offered alone.
    assert "# all 5 air loops' supply air" not in text and "5 single-zone unit(s) left out" in text
    assert text.count('_supply_equipment_outlet_node_setpoint_c"') == 5
    # Comfort is scored while its People follow their schedule; energy counts every fuel it meters.
    assert spec.reward.occupied is not None and spec.reward.occupied.observation == "occupancy"
    assert any(o.variable == "Schedule Value" and o.key == "BLDG_OCC_SCH_wo_SB" for o in spec.observations)
    assert spec.reward.energy_terms == ("power_w", "naturalgas_w")
    # Every candidate names an actuator EnergyPlus listed for this model.
    (surveyed,) = surveys
    listed = {(r[1], r[2], r[3].upper()) for r in surveyed.rows if r[0] == "Actuator"}
    for a in actions:
        assert (a.actuators[0].component, a.actuators[0].control, a.actuators[0].key.upper()) in listed


@pytest.mark.slow
def test_air_loops_on_different_own_plans_get_one_supply_air_knob_each(tmp_path, monkeypatch):
    """The DOE out-patient clinic: AHU-1 holds 11.1 C, AHU-2 12.8 C. One shared value would keep one of them off its
    own plan at every step (its trained planner spent 3 % more HVAC energy), so each own plan gets its knob. The
    loops' plans are constant: a day's survey sees them as the week's does (the week: the prototype's test above)."""
    from parallel_eplus.buildings.starter import write

    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    monkeypatch.setattr(write, "survey", functools.partial(write.survey, days=1.0))
    out = tmp_path / "clinic.toml"
    init_spec(Path(dataset.ref_models["outpatient"]), "CO", out)
    text = out.read_text()
    assert "the 2 air loops' own supply air differs (seen 11.1..11.1 C, 12.8..12.8 C)" in text
    assert "# all 2 air loops' supply air together" not in text
    out.write_text(uncomment_actions(text, r"^# the one air loop's supply air on its own plan"))
    knobs = {a.name: ([x.key for x in a.actuators], a.low, a.high, a.initial) for a in load_spec(out).actions}
    assert knobs == {
        "supply_air_ahu_1_c": (["AHU-1 Supply Equipment Outlet Node"], 11.0, 18.0, 11.1),
        "supply_air_ahu_2_c": (["AHU-2 Supply Equipment Outlet Node"], 12.0, 18.0, 12.8),
    }


@pytest.mark.slow
def test_init_offers_the_air_loops_supply_air_ready_to_uncomment_and_check_proves_it(tmp_path, monkeypatch, no_leaks):
    """The DOE medium office as it ships: its three air loops' supply air, each set by a SetpointManager:Scheduled
    that each run's copy replaces, offered with the loop, the manager and the range; uncommented, `check` passes and
    proves each loop's supply air follows; outdoor air and fan flows are offered too, ventilation named."""
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    out = tmp_path / "office.toml"
    init_spec(Path(dataset.ref_models["medium_office"]), "CO", out)
    text = out.read_text()
    assert "# node VAV_1 Supply Equipment Outlet Node: supply air of AirLoopHVAC VAV_1 (seen 12.8..12.8 C)" in text
    assert '# # replaced in each run\'s copy: SetpointManager:Scheduled "VAV_1 SAT setpoint"' in text
    assert "disable the manager" not in text  # no hand edit of the model any more
    assert 'component = "Outdoor Air Controller", control = "Air Mass Flow Rate", key = "VAV_1_OA_Controller"' in text
    assert 'readback = { variable = "System Node Mass Flow Rate", key = "VAV_1_OAInlet Node" }' in text
    assert "Fan Pressure Rise (duct static pressure) is listed for 3 fan(s), not offered" in text
    out.write_text(uncomment_actions(text, r"^# (all 3 air loops' supply air|outdoor air of VAV_1 )"))
    supply, oa = load_spec(out).actions
    assert (supply.name, supply.low, supply.high, len(supply.actuators)) == ("supply_air_c", 12.0, 18.0, 3)
    assert oa.readback == ("System Node Mass Flow Rate", "VAV_1_OAInlet Node") and 0 <= oa.low < oa.high
    from parallel_eplus.buildings.check.names import check_spec

    result = check_spec(out, use_cache=False)
    assert result.ok, result.problems
    assert sum("supply_air_c reaches VAV_" in n for n in result.notes) == 6  # three loops, both ends
    assert sum('prepared copy: SetpointManager:Scheduled "VAV_' in n for n in result.notes) == 3


def test_init_bad_model_fails_with_a_message(tmp_path):
    with pytest.raises(FileNotFoundError, match="model file not found"):
        init_spec(tmp_path / "missing.idf")
    broken = tmp_path / "broken.idf"
    broken.write_text("Version,25.2;\nZone,;\n")
    with pytest.raises(ValueError, match="stopped before its first timestep"):
        init_spec(broken)
    assert not (tmp_path / "broken.toml").exists()


@pytest.mark.slow
def test_an_unmodified_prototype_from_init_to_evaluate(tmp_path, monkeypatch, capsys, no_leaks):
    """The wheel's small office as it ships (it simulates only its design days): init, check, train and evaluate
    with no edit of the model; the engine prepares each run's copy, and the user's file stays as it was."""
    monkeypatch.chdir(tmp_path)
    idf = tmp_path / "office.idf"
    shutil.copy(dataset.ref_models["small_office"], idf)
    original = idf.read_bytes()
    assert main(["building", "init", str(idf), "--weather", "CO", "-o", "office.toml"]) == 0
    spec = tmp_path / "office.toml"
    spec.write_text(uncomment_actions(spec.read_text(), r"^# all 5 thermostats' (cooling|heating)"))
    reward = load_spec(spec).reward  # its furnaces burn gas: the energy figure counts it
    assert reward.energy == ("power_w", "naturalgas_w") and reward.occupied is not None
    assert (reward.thermostat, reward.objective, load_spec(spec).preset) == (True, "hvac", "thermostat-planner")
    assert main(["building", "check", str(spec), "--no-cache"]) == 0
    train = ["train", "--building", str(spec), "--algorithm", "trpo", "--weathers", "CO", "--workers", "1",
             "--run-days", "1", "--timesteps", "144", "--batch-size", "144", "--run-name", "office",
             "--quiet"]  # fmt: skip
    assert main(train) == 0
    out = tmp_path / "eval"
    evaluate = ["evaluate", "--building", str(spec), "--policy", "runs/office/model.zip", "--baseline",
                "--weathers", "CO", "--run-days", "2", "--workers", "2", "--out", str(out), "--quiet"]  # fmt: skip
    assert main(evaluate) == 0
    results = (out / "results.csv").read_text()
    assert results.count("\n") == 3  # a header, the built-in controls and the policy
    assert idf.read_bytes() == original
    capsys.readouterr()
