"""Building spec files: the data center's spec states exactly model.py's facts; bad specs name every problem."""

from __future__ import annotations

from pathlib import Path

import pytest

from parallel_eplus.buildings import datacenter as model
from parallel_eplus.buildings.scoring.reward import RewardConfig, reward_config
from parallel_eplus.buildings.spec.load import SpecError, load_spec

SPEC = Path(model.__file__).parent / "specs" / "datacenter-2zone.toml"


def test_datacenter_spec_matches_model():
    spec = load_spec(SPEC)
    assert spec.idf == model.AGENT_IDF and spec.baseline_idf == model.BASELINE_IDF
    assert [(o.name, o.variable, o.key, o.low, o.high) for o in spec.observations] == [
        (s.name, s.variable, s.key, s.low, s.high) for s in model.SENSORS
    ]
    assert [(a.name, a.low, a.high, a.initial) for a in spec.actions] == [
        (a.name, a.low, a.high, a.initial) for a in model.ACTIONS
    ]
    for got, want in zip(spec.actions, model.ACTIONS, strict=True):
        assert [(x.component, x.control, x.key) for x in got.actuators] == [
            (x.component_type, x.control_type, x.key) for x in want.actuators
        ]
    assert spec.reward.temperatures == model.ZONE_TEMP_NAMES
    assert spec.reward.band == model.COMFORT_BAND_C
    assert reward_config(spec) == RewardConfig()
    assert all(p.is_file() for p in spec.weathers.values())


def test_bad_spec_reports_every_problem(tmp_path):
    text = SPEC.read_text().replace("low = 1.75", "low = 40.0").replace('power = "power_w"', 'power = "powr_w"')
    text = text.replace("band_weight = 0.1", "band_wieght = 0.1").replace('\nidf = "2Zone', '\nidf = "/nowhere/2Zone')
    bad = tmp_path / "bad.toml"
    bad.write_text(text)
    with pytest.raises(SpecError) as e:
        load_spec(bad)
    msg = str(e.value)
    assert "actions[2].low: 40.0 is not below high 7.0" in msg
    assert 'reward.power: "powr_w" is not an observation name; close: "power_w"' in msg
    assert 'reward.band_wieght: unknown reward parameter; close: "band_weight"' in msg
    assert "actions[3].low: 40.0 is not below high 7.0" in msg
    assert "idf: " in msg and "6 problem(s)" in msg
    assert 'baseline_idf: "2ZoneDataCenterHVAC_wEconomizer.idf" not found' in msg  # bare names: built-in specs only


def test_malformed_toml(tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text('name = "x\n')
    with pytest.raises(SpecError, match="malformed TOML"):
        load_spec(bad)


def test_temp_spec_is_the_setpoint_half():
    temp = load_spec(SPEC.with_name("datacenter-2zone-temp.toml"))
    assert [a.name for a in temp.actions] == [a.name for a in model.control_model("temp").actions]
    assert temp.observations == load_spec(SPEC).observations
