"""`building check`: every name in a spec resolved through EnergyPlus, every problem reported at once (real runs)."""

from __future__ import annotations

import pytest

from parallel_eplus.buildings.check.names import check_spec, require_checked
from parallel_eplus.buildings.resources import model_file, spec_dir
from parallel_eplus.buildings.spec.load import SpecError
from parallel_eplus.cli import main

SHIPPED = spec_dir() / "datacenter-2zone.toml"


@pytest.fixture(autouse=True)
def private_cache(tmp_path, monkeypatch):
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))


def _spec_with(tmp_path, *replacements: tuple[str, str]):
    text = SHIPPED.read_text()
    for old, new in replacements:
        assert old in text, old
        text = text.replace(old, new, 1)
    for key in ("idf", "baseline_idf"):  # a user's spec elsewhere names the models by path
        name = text.split(f'\n{key} = "', 1)[1].split('"', 1)[0]
        text = text.replace(f'{key} = "{name}"', f'{key} = "{model_file(name)}"', 1)
    path = tmp_path / "mine.toml"
    path.write_text(text)
    return path


@pytest.mark.slow
def test_the_shipped_spec_resolves_and_the_pass_is_cached(tmp_path):
    first = check_spec(SHIPPED)
    assert first.ok and not first.cached and first.timesteps_per_hour == 4
    assert check_spec(SHIPPED).cached
    edited = _spec_with(tmp_path, ('name = "datacenter-2zone"', 'name = "datacenter-2zone-mine"'))
    assert not check_spec(edited).cached  # another file, another key


def test_typos_are_all_reported_with_the_key_and_the_close_name(tmp_path, no_leaks):
    spec = _spec_with(
        tmp_path,
        ('key = "East Zone"', 'key = "East Zonee"'),
        ('key = "West Air Loop Outlet Node"', 'key = "West Air Loop Outlet Nod"'),
        ('component = "Fan"', 'component = "Fann"'),
    )
    with pytest.raises(SpecError) as e:
        require_checked(spec)
    lines = str(e.value).splitlines()[1:]
    assert len(lines) == 3, e.value
    assert (
        'observations[2]: no key "East Zonee" for variable "Zone Mean Air Temperature"; close: "East Zone"' in lines[0]
    )
    assert 'on "West Air Loop Outlet Nod"; close: "West Air Loop Outlet Node"' in lines[1]
    assert lines[1].strip().startswith("actions[0].actuators[3]:")
    assert 'actions[2].actuators[0]: no actuator type "Fann/Fan Air Mass Flow Rate"; close: "Fan/' in lines[2]
    assert not check_spec(spec).cached  # a failed check is never cached


@pytest.mark.slow
def test_the_2025_meter_handle_gap_is_named(tmp_path):
    spec = _spec_with(
        tmp_path,
        (
            'variable = "Facility Total Electricity Demand Rate"\nkey = "Whole Building"',
            'meter = "Electricity:Facility"',
        ),
    )
    problems = check_spec(spec).problems
    assert len(problems) == 1 and "Facility Total Electricity Demand Rate" in problems[0], problems


@pytest.mark.slow
def test_a_model_energyplus_rejects_is_one_clear_problem(tmp_path, no_leaks):
    broken = tmp_path / "broken.idf"
    broken.write_text(
        model_file("2ZoneDataCenterHVAC_wEconomizer_agent.idf").read_text().replace("Timestep,", "Timestepp,", 1)
    )
    spec = _spec_with(tmp_path)
    spec.write_text(spec.read_text().replace(str(model_file("2ZoneDataCenterHVAC_wEconomizer_agent.idf")), str(broken)))
    problems = check_spec(spec).problems
    assert len(problems) == 1 and "EnergyPlus rejected" in problems[0] and "broken.idf" in problems[0], problems


@pytest.mark.slow
def test_cli_exit_codes(tmp_path, capsys):
    assert main(["building", "check", str(SHIPPED)]) == 0
    assert "datacenter-2zone: ok: 6 observations, 4 actions (10 actuators)" in capsys.readouterr().out
    bad = _spec_with(tmp_path, ('key = "West Zone"', 'key = "Wset Zone"'))
    assert main(["building", "check", str(bad)]) == 1
    assert 'close: "West Zone"' in capsys.readouterr().err
