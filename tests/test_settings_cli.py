"""Settings a user types: `--mpc`/`--sac`/`--mbpo NAME=VALUE` read by type and refused by name, `--mpc help`,
`train --help` in groups with help for every option, and `train --config run.toml` under the command line.

All but the last test parse only (no EnergyPlus); the last trains one short real run from a config file.
"""

from __future__ import annotations

import argparse
import json
from dataclasses import fields

import pytest

from parallel_eplus.cli import main
from parallel_eplus.cli.parser import build_parser
from parallel_eplus.learning.model_based.settings import MBPOSettings, MPCSettings
from parallel_eplus.learning.settings import SACSettings, show, type_name

from .conftest import our_processes

SETTINGS = [MPCSettings, SACSettings, MBPOSettings]


def test_a_boolean_setting_takes_only_a_boolean():
    with pytest.raises(ValueError, match=r"--mpc consensus='ture': a boolean: true, false, yes, no, on, off, 1 or 0"):
        MPCSettings.from_text("consensus=ture")
    for text, value in (("YES", True), ("on", True), ("1", True), ("False", False), ("off", False), ("0", False)):
        assert MPCSettings.from_text(f"consensus={text}").consensus is value


def test_an_integer_setting_takes_only_a_whole_number():
    with pytest.raises(ValueError, match=r"--mpc horizon='2.7': a whole number, e.g. 8"):
        MPCSettings.from_text("horizon=2.7")
    with pytest.raises(ValueError, match=r"--sac buffer_size='lots': a whole number"):
        SACSettings.from_text("buffer_size=lots")
    with pytest.raises(ValueError, match=r"--mbpo rollout_batch='1.5'"):
        MBPOSettings.from_text("rollout_batch=1.5")
    settings = MPCSettings.from_text("horizon=1e1,explore_steps=2_000,candidates=64.0")
    assert (settings.horizon, settings.explore_steps, settings.candidates) == (10, 2000, 64)
    assert isinstance(settings.horizon, int)


def test_numbers_choices_none_and_layer_sizes_are_read_by_their_annotation():
    with pytest.raises(ValueError, match=r"--mpc min_saving='nan': a finite number"):
        MPCSettings.from_text("min_saving=nan")
    with pytest.raises(ValueError, match=r"--mpc comfort_risk='max': one of 'mean' or 'worst'"):
        MPCSettings.from_text("comfort_risk=max")
    with pytest.raises(ValueError, match=r"band_thermostats='some': one of 'free', 'at_least_baseline' or 'baseline'"):
        MPCSettings.from_text("band_thermostats=some")
    with pytest.raises(ValueError, match="horizon takes a value, not none"):
        MPCSettings.from_text("horizon=none")
    with pytest.raises(ValueError, match="layer sizes"):
        SACSettings.from_text("net_arch=64x0")
    with pytest.raises(ValueError, match="ent_coef 'sometimes'"):
        SACSettings.from_text("ent_coef=sometimes")
    # `float | None`: the annotation, not the default's type (None), says a number is wanted
    assert MPCSettings.from_text("comfort_weight=2").comfort_weight == 2.0
    assert MPCSettings.from_text("comfort_weight=2,comfort_weight=none").comfort_weight is None  # the last counts
    assert MBPOSettings.from_text("rail_k=none").rail_k is None
    assert SACSettings.from_text("net_arch=128x128").net_arch == (128, 128)
    # a saved planner's settings are re-read with another flag's name in errors (evaluate --planner)
    with pytest.raises(ValueError, match=r"--planner distill='maybe'"):
        MPCSettings.from_text("distill=maybe", flag="--planner")
    with pytest.raises(ValueError, match="comfort_level 'mine'"):  # built in code, the Literal still holds
        MPCSettings(comfort_level="mine")


def test_an_unknown_setting_is_named_with_the_nearest():
    with pytest.raises(ValueError, match=r"--mpc 'horizn=3': expected NAME=VALUE with NAME one of .*close: .horizon."):
        MPCSettings.from_text("horizn=3")
    with pytest.raises(ValueError, match=r"--mbpo 'consensus=true': expected NAME=VALUE"):
        MBPOSettings.from_text("consensus=true")


def test_a_bad_setting_stops_train_with_a_clean_error_before_anything_runs(tmp_path, monkeypatch, caplog):
    monkeypatch.chdir(tmp_path)
    assert main(["train", "--workers", "1", "--mpc", "consensus=ture", "--algorithm", "mpc"]) == 2
    assert "--mpc consensus='ture': a boolean" in caplog.text
    assert not (tmp_path / "runs").exists() and our_processes() == []


@pytest.mark.parametrize("settings", SETTINGS, ids=lambda c: c.flag)
def test_help_lists_every_setting_with_its_type_and_default(settings, capsys):
    with pytest.raises(SystemExit) as done:
        main(["train", settings.flag, "help"])
    assert done.value.code == 0
    lines = capsys.readouterr().out.splitlines()
    header = next(line for line in lines if line.split()[:1] == ["setting"])
    at = [header.index(column) for column in ("type", "default", "description")]
    rows = {line.split()[0]: line for line in lines if line.startswith("  ") and not line.startswith("   ")}
    for f in fields(settings):
        assert f.name in rows, f"{settings.flag} help does not list {f.name}"
        row = rows[f.name]
        type_, default, description = row[at[0] : at[1]].strip(), row[at[1] : at[2]].strip(), row[at[2] :]
        assert (type_, default) == (type_name(settings.hints()[f.name]), show(f.default)), f.name
        assert f.metadata["help"].startswith(description.split()[0]), f.name  # its one line, from the field


def test_planner_options_help_names_the_forecast_and_the_settings(capsys):
    with pytest.raises(SystemExit) as done:
        main(["evaluate", "--planner", "help"])
    out = capsys.readouterr().out
    assert done.value.code == 0 and "forecast=perfect|low|medium|high" in out and "  candidates " in out


def _subparsers(parser: argparse.ArgumentParser, prefix=("parallel-eplus",)):
    yield prefix, parser
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, sub in action.choices.items():
                yield from _subparsers(sub, (*prefix, name))


def test_train_help_is_grouped_and_every_option_explains_itself():
    commands = dict(_subparsers(build_parser()))
    train = commands[("parallel-eplus", "train")]
    text = train.format_help()
    groups = ["run:", "building, weather and observations", "algorithm", "comfort and objective", "residual",
              "workers and backend", "evaluation during training"]  # fmt: skip
    titles = [g.title for g in train._action_groups]
    for group in groups:
        assert any(t.startswith(group) for t in titles), (group, titles)
        assert group in text
    for title in titles[2:]:  # each of ours holds options (argparse's own two come first)
        assert next(g for g in train._action_groups if g.title == title)._group_actions, title
    # every subcommand declared in cli/parser.py and train_parser.py (export and serve are cli/deploy.py's)
    silent = [
        f"{' '.join(name)} {'/'.join(a.option_strings) or a.dest}"
        for name, parser in commands.items()
        if not {"export", "serve"} & set(name)
        for a in parser._actions
        if not a.help and not isinstance(a, argparse._SubParsersAction)
    ]
    assert silent == []
    top = build_parser().format_help()
    line = " ".join(top[top.index("    train") :].split("\n    sweep")[0].split())
    assert all(name in line for name in ("TRPO", "PPO", "SAC", "mpc", "MBPO")), line


def _parse(*argv):
    return build_parser().parse_args(["train", *argv])


def test_config_file_values_are_defaults_the_command_line_overrides(tmp_path, capsys):
    run = tmp_path / "run.toml"
    run.write_text(
        'workers = 1\nweathers = ["CA", "CO"]\nrun-days = 3\nrun_name = "from-file"\ntime-features = true\n'
        'algorithm = "mpc"\ncomfort-target = 99.6\ninit-from = "runs/base/model.zip"\nweather-noise = true\n'
        "[mpc]\nhorizon = 12\nconsensus = true\n"
    )
    args = _parse("--config", str(run))
    assert (args.workers, args.weathers, args.run_days, args.run_name) == (1, "CA,CO", 3, "from-file")
    assert args.time_features is True
    assert (args.algorithm, args.comfort_target, str(args.init_from)) == ("mpc", 99.6, "runs/base/model.zip")
    assert args.weather_noise == "default" and args.mpc == "horizon=12,consensus=true"
    assert args.seed == 0 and args.batch_size == 16384  # what the file leaves out keeps its default
    assert set(args.from_config) >= {"workers", "run_days", "mpc"}

    args = _parse("--run-days", "5", "--config", str(run), "--workers", "2", "--mpc", "horizon=4,candidates=64")
    assert (args.run_days, args.workers, args.weathers) == (5, 2, "CA,CO")  # flags win, before or after --config
    settings = MPCSettings.from_text(args.mpc)  # the file's [mpc], then the command line's on top
    assert (settings.horizon, settings.consensus, settings.candidates) == (4, True, 64)

    run.write_text('mpc = "horizon=6"\nquiet = false\n')  # --mpc as its own text; a flag set false stays off
    args = _parse("--config", str(run))
    assert args.mpc == "horizon=6" and args.quiet is False


@pytest.mark.parametrize(
    ("text", "error"),
    [
        ("wokers = 2\n", "unknown setting 'wokers'; close: \"workers\""),
        ("workers = 2.5\n", "workers = 2.5: a whole number"),
        ('time-features = "yes"\n', "time-features = 'yes': true or false"),
        ('algorithm = "a2c"\n', "algorithm = 'a2c': one of trpo, ppo, sac, mpc, mbpo"),
        ("residual = true\n", "residual = True: not a boolean"),
        ('config = "other.toml"\n', "a config file cannot name another"),
        ("workers = \n", "not valid TOML"),
    ],
)
def test_a_config_file_key_it_cannot_mean_is_an_error_naming_it(tmp_path, capsys, text, error):
    run = tmp_path / "run.toml"
    run.write_text(text)
    with pytest.raises(SystemExit) as done:
        _parse("--config", str(run))
    assert done.value.code == 2
    assert f"--config {run}: {error}" in capsys.readouterr().err


@pytest.mark.slow
def test_a_run_from_a_config_file_saves_the_resolved_settings(tmp_path, monkeypatch, no_leaks):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "run.toml").write_text(
        'workers = 1\nweathers = "CA"\nrun-days = 1\ntimesteps = 64\nbatch-size = 64\nrun-name = "from-file"\n'
        "gamma = 0.95\nquiet = true\nseed = 5\n[sac]\nent_coef = 0.05\n"
    )
    args = ["train", "--preset", "paper-trpo", "--config", "run.toml", "--seed", "3", "--checkpoint-every", "64"]
    assert main(args) == 0
    saved = json.loads((tmp_path / "runs" / "from-file" / "config.json").read_text())
    assert (saved["workers"], saved["weathers"], saved["run_days"], saved["batch_size"]) == (1, ["CA"], 1, 64)
    assert saved["trpo"]["gamma"] == 0.95 and saved["sac"]["ent_coef"] == "0.05"  # the file's
    assert saved["seed"] == 3 and saved["checkpoint_every"] == 64  # the command line's, over the file's seed
    assert saved["preset"] == "paper-trpo" and saved["algorithm"] == "trpo"  # the preset it started from


@pytest.mark.parametrize("flag", ["--planner", "--planner-options"])
def test_planner_options_are_refused_naming_the_option_they_came_from(flag):
    from parallel_eplus.learning.model_based.control.saved_planner import PlannerOptions

    for text, what in [("consensus=ture", "a boolean"), ("seed=2.7", "a whole number"), ("forecast=exact", "one of")]:
        with pytest.raises(ValueError, match=f"^{flag} .*{what}"):
            PlannerOptions.parse(text, flag=flag)
