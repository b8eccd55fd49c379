"""`building check`: every typo in a spec's EnergyPlus names is reported at once, with close matches."""

from __future__ import annotations

from pathlib import Path

import pytest

from parallel_eplus.buildings import check, model
from parallel_eplus.buildings.spec import SpecError
from parallel_eplus.cli import main

SPEC = Path(model.__file__).parent / "specs" / "datacenter-2zone.toml"


def _typo_spec(tmp_path: Path) -> Path:
    text = SPEC.read_text().replace('idf = "../../../', f'idf = "{SPEC.parents[3]}/')
    text = text.replace('key = "West Air Loop Outlet Node"', 'key = "West Air Loop Outlet Nod"')
    text = text.replace('key = "East Zone"', 'key = "East Zon"')
    text = text.replace(
        'control = "Fan Air Mass Flow Rate", key = "West', 'control = "Fan Air Mass Flow Rat", key = "West'
    )
    text = text.replace('"Facility Total HVAC Electricity Demand Rate"', '"Facility Total HVAC Electricity Demand Rat"')
    path = tmp_path / "typo.toml"
    path.write_text(text.replace("../../../weather/", f"{SPEC.parents[3]}/weather/"))
    return path


def test_check_names_every_typo(tmp_path, monkeypatch, no_leaks):
    monkeypatch.setattr(check, "CACHE_DIR", tmp_path / "cache")
    with pytest.raises(SpecError) as e:
        check.check_building(_typo_spec(tmp_path))
    msg = str(e.value)
    assert "4 problem(s)" in msg
    assert (
        'actions[0].actuators[3]: no actuator "System Node Setpoint/Temperature Setpoint" on '
        '"West Air Loop Outlet Nod"; close: "WEST AIR LOOP OUTLET NODE"'
    ) in msg
    assert 'observations[2].key: no variable "Zone Mean Air Temperature" on "East Zon"; close: "EAST ZONE"' in msg
    assert (
        'actions[2].actuators[0]: no actuator type "Fan/Fan Air Mass Flow Rat"; close: "Fan/Fan Air Mass Flow Rate"'
        in msg
    )
    assert "observations[5].variable: no variable" in msg
    assert not list((tmp_path / "cache").glob("*.json"))  # a failed check is not remembered


def test_check_passes_and_caches(tmp_path, monkeypatch, capsys, no_leaks):
    monkeypatch.setattr(check, "CACHE_DIR", tmp_path / "cache")
    assert main(["building", "check", str(SPEC)]) == 0
    assert "6 observations and 10 actuators resolve" in capsys.readouterr().out
    check.check_building(SPEC)
    assert len(list((tmp_path / "cache").glob("*.json"))) == 1
    monkeypatch.setattr(check, "run_check", lambda *a: pytest.fail("a cached check ran EnergyPlus again"))
    check.check_building(SPEC)


def test_cli_reports_typos(tmp_path, monkeypatch, caplog, no_leaks):
    monkeypatch.setattr(check, "CACHE_DIR", tmp_path / "cache")
    assert main(["building", "check", str(_typo_spec(tmp_path))]) == 2
    assert "West Air Loop Outlet Nod" in caplog.text
