"""Presets shipped in the package (parallel_eplus/presets/): listed and shown, read as defaults under a `--config`
file's and the command line's, and chosen by the building's kind when a user names no algorithm. Parsing only: the
run that records its preset is tests/test_settings_cli.py's (one real training run for both)."""

from __future__ import annotations

import pytest

from parallel_eplus.cli import main
from parallel_eplus.cli.parser import build_parser
from parallel_eplus.learning.model_based.settings import MPCSettings
from parallel_eplus.presets.catalog import KINDS, load_preset, names


def test_every_shipped_preset_reads_and_its_settings_are_options_of_its_command():
    parser = build_parser()
    assert {"paper-trpo", "thermostat-planner"} <= set(names())
    for name in names():
        preset = load_preset(name)
        assert preset.kind in KINDS and preset.reason.strip() and preset.evidence.startswith("results/")
        for command in preset.commands:
            args = parser.parse_args([command, "--preset", name])  # each value checked as its option checks it
            assert args.preset == name
        if "mpc" in preset.defaults("train"):
            MPCSettings.from_text(preset.defaults("train")["mpc"])  # every setting typed and known


def test_presets_lists_them_and_shows_one_with_every_setting(capsys):
    assert main(["presets"]) == 0
    listed = capsys.readouterr().out
    assert all(name in listed for name in names())
    assert main(["presets", "thermostat-planner"]) == 0
    shown = capsys.readouterr().out
    assert "--mpc max_increment=2.0" in shown and "--planner band_thermostats=baseline" in shown
    assert "Evidence:" in shown
    assert main(["presets", "no-such"]) == 2


def test_a_preset_is_under_the_config_file_which_is_under_the_command_line(tmp_path):
    (tmp_path / "run.toml").write_text("run-days = 7\ncomfort-margin = 0.2\n[mpc]\nhorizon = 8\n")
    args = build_parser().parse_args(["train", "--preset", "thermostat-planner", "--config", str(tmp_path / "run.toml"),
                                      "--comfort-margin", "0.3", "--mpc", "candidates=64"])  # fmt: skip
    assert args.algorithm == "mpc" and args.objective == "hvac" and args.comfort_target == 99.8  # the preset's
    assert args.run_days == 7  # the file's over the preset's 14
    assert args.comfort_margin == 0.3  # the command line's over both
    mpc = MPCSettings.from_text(args.mpc)
    assert (mpc.max_increment, mpc.horizon, mpc.candidates) == (2.0, 8, 64)  # each source's, the later winning


def test_the_building_chooses_the_preset_when_the_user_names_no_algorithm():
    parser = build_parser()
    small = parser.parse_args(["train", "--building", "office-small"])
    assert (small.preset, small.algorithm, small.objective) == ("thermostat-planner", "mpc", "hvac")
    assert parser.parse_args(["train", "--building", "office-medium"]).preset == "thermostat-planner-on-reset"
    chosen = parser.parse_args(["train", "--building", "office-small", "--algorithm", "ppo"])
    assert (chosen.preset, chosen.algorithm) == (None, "ppo")  # an algorithm named: no preset under it
    paper = parser.parse_args(["train", "--building", "datacenter-2zone"])
    assert (paper.preset, paper.algorithm) == (None, "trpo")  # the paper's data center keeps the paper's TRPO
    assert parser.parse_args(["train"]).algorithm == "trpo"


def test_evaluate_takes_a_presets_planner_settings_under_its_own():
    args = build_parser().parse_args(["evaluate", "--preset", "thermostat-planner", "--planner", "candidates=64"])
    assert args.planner == "band_thermostats=baseline,candidates=64"


@pytest.mark.parametrize("bad", ["paper", "../specs/office-small"])
def test_an_unknown_preset_is_refused_naming_the_ones_there_are(bad, capsys):
    with pytest.raises(SystemExit) as e:
        build_parser().parse_args(["train", "--preset", bad])
    assert e.value.code == 2 and "thermostat-planner" in capsys.readouterr().err


def test_a_spec_names_its_preset_and_a_preset_it_cannot_mean_is_refused(tmp_path):
    from parallel_eplus.buildings.resources import spec_file
    from parallel_eplus.buildings.spec import SpecError, load_spec

    text = spec_file("office-small").read_text()  # its model is found by name, wherever the spec is
    named = tmp_path / "named.toml"
    named.write_text(text.replace('name = "', 'preset = "datacenter-planner"\nname = "', 1))
    assert load_spec(named).preset == "datacenter-planner"
    assert build_parser().parse_args(["train", "--building", str(named)]).preset == "datacenter-planner"
    bad = tmp_path / "bad.toml"
    bad.write_text(text.replace('name = "', 'preset = "thermostat-planer"\nname = "', 1))
    with pytest.raises(SpecError, match="thermostat-planner"):
        load_spec(bad)


def test_a_config_file_may_name_the_preset_its_settings_start_from(tmp_path):
    (tmp_path / "run.toml").write_text('preset = "thermostat-planner"\nrun-days = 7\n')
    args = build_parser().parse_args(["train", "--config", str(tmp_path / "run.toml")])
    assert (args.preset, args.algorithm, args.objective, args.run_days) == ("thermostat-planner", "mpc", "hvac", 7)
    chosen = build_parser().parse_args(["train", "--config", str(tmp_path / "run.toml"), "--preset", "paper-trpo"])
    assert (chosen.preset, chosen.algorithm, chosen.run_days) == ("paper-trpo", "trpo", 7)
