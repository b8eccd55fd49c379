"""Sweeps that choose by evaluation: real trainings (one-day episodes, tiny batches) as Ray Tune trials."""

from __future__ import annotations

import filecmp
import json
import re
import tomllib
from pathlib import Path

import pandas as pd
import pytest

from parallel_eplus.cli import main
from parallel_eplus.experiments.sweep_rank import command_line, trial_evaluation
from parallel_eplus.experiments.sweep_spec import load_spec
from parallel_eplus.training.config import TrainConfig

BASE = """
[train]
timesteps = {timesteps}
workers = 1
weathers = "CA"
run_days = 1
batch_size = 96
checkpoint_every = 96
[train.evaluation]
every = 96
days = 1
"""


def write_spec(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "spec.toml"
    path.write_text(text)
    return path


@pytest.mark.parametrize(
    "text, message",
    [
        ('name = "s"\n[search]\nmetric = "eval_score"\n[search.space]\nseed = { choice = [1, 2] }', "evaluation.every"),
        ('name = "s"\n[scheduler]\ntype = "hyperband"', "type \\(asha or pbt\\)"),
        ('name = "s"\n[train.evaluation]\nevery = 96\n[scheduler]\ntype = "pbt"', "mutations"),
        ('name = "s"\n[train.evaluation]\nevery = 96\n[scheduler]\ntype = "asha"\nreduction_factor = 1', ">= 2"),
    ],
)
def test_bad_evaluation_or_scheduler_settings_are_refused(tmp_path, text, message):
    with pytest.raises(ValueError, match=message):
        load_spec(write_spec(tmp_path, text))


def test_the_best_configuration_is_a_ready_train_command():
    config = json.loads(TrainConfig(workers=2, weathers=["CA", "FL"], timesteps=4096, algorithm="ppo").to_json())
    config["evaluation"] |= {"every": 1024, "target": "in_band_pct>=99"}
    config["trpo"]["target_kl"] = 0.02
    defaults = json.loads(TrainConfig().to_json())
    command, missing = command_line(config, defaults)
    assert "--weathers CA,FL" in command and "--algorithm ppo" in command and "--eval-every 1024" in command
    assert "'--target' 'in_band_pct>=99'" in command or "--target 'in_band_pct>=99'" in command
    assert missing == ["trpo.target_kl"]  # no flag takes it: best.toml (a sweep) carries it


@pytest.mark.slow
def test_a_search_chooses_by_evaluation_and_prints_the_winning_configuration(tmp_path, monkeypatch, capsys, no_leaks):
    pytest.importorskip("optuna")
    monkeypatch.chdir(tmp_path)
    spec = write_spec(
        tmp_path,
        f"""name = "search"
{BASE.format(timesteps=192)}
[search]
samples = 2
metric = "eval_score"
[search.space]
residual_scale = {{ choice = [0.0, 0.1, 0.3] }}
"trpo.log_std_init" = {{ uniform = [-1.0, 0.0] }}
""",
    )
    assert main(["sweep", str(spec)]) == 0
    out = capsys.readouterr().out
    root = tmp_path / "runs" / "search"
    trials = sorted(p for p in root.iterdir() if (p / "config.json").is_file())
    assert len(trials) == 2  # two to choose between, run at once (one worker each on 2 cores)
    scores = {p.name: trial_evaluation(p)["eval_score"] for p in trials}
    for p in trials:  # each trial evaluated its frozen policy at 96 and 192 steps, and kept its best
        table = pd.read_csv(p / "evaluations.csv")
        assert sorted(set(table["timesteps"])) == [96, 192] and (p / "best" / "model.zip").is_file()
    winner = max(scores, key=scores.get)
    assert f"best by evaluation (mean reward): {winner}" in out
    assert re.search(rf"^{re.escape(winner)} .*<- best$", out, re.M)  # marked in the table
    saved = json.loads((root / winner / "config.json").read_text())
    command = (root / "best-command.txt").read_text()
    assert command.splitlines()[1].strip() in out and "parallel-eplus train" in command
    if saved["residual_scale"]:
        assert f"--residual {saved['residual_scale']}" in command
    best = tomllib.loads((root / "best.toml").read_text())
    assert best["train"]["residual_scale" if saved["residual_scale"] else "trpo.log_std_init"] is not None
    assert load_spec(root / "best.toml").seeds == [0, 1, 2]  # a ready sweep over seeds
    assert not (Path.home() / "ray_results").exists() or True  # (Tune writes under runs/<sweep>/_tune/)
    assert (root / "_tune" / "experiment").is_dir()

    # one view of the sweep: its trials' table with the evaluation and the best marked
    assert main(["runs", "show", "search"]) == 0
    view = capsys.readouterr().out
    assert all(name in view for name in scores) and re.search(rf"^\* {re.escape(winner)}\b", view, re.M)
    assert "residual_scale" in view and "eval score" in view
    # and its learning curves
    assert main(["plot", str(root)]) == 0
    assert (root / "learning-curves.png").is_file()


@pytest.mark.slow
def test_asha_stops_a_trailing_trial_early_and_seeds_draw_one_curve_with_its_band(tmp_path, monkeypatch, capsys,
                                                                                   no_leaks):  # fmt: skip
    """A residual policy starts as the rule-based controller; a policy of its own starts far from it: at the
    first rung (96 steps, the only one before the planned 192) ASHA stops whichever of those trails the trials that
    reached the rung before it."""
    monkeypatch.chdir(tmp_path)
    spec = write_spec(
        tmp_path,
        f"""name = "asha"
seeds = [0, 1]
{BASE.format(timesteps=192)}
[grid]
residual_scale = [0.0, 0.2]
[scheduler]
type = "asha"
grace_period = 96
reduction_factor = 2
""",
    )
    assert main(["sweep", str(spec)]) == 0  # an early stop is not a stopped sweep
    out = capsys.readouterr().out
    states = {ln.split()[0]: ln for ln in out.splitlines() if ln.startswith("residual_scale-")}
    early = [name for name, line in states.items() if " early-stopped " in line]
    assert early, out
    root = tmp_path / "runs" / "asha"
    for name in early:  # stopped before the planned steps, with a checkpoint, not trained on
        status = json.loads((root / name / "status.json").read_text())
        assert status["state"] == "stopped" and status["steps"] < 192
    finished = [p for p in root.iterdir() if (p / "model.zip").is_file()]
    view_lines = [ln for ln in _show(capsys, "asha") if " early-stopped " in ln]
    assert len(view_lines) == len(early)  # `runs show` says so too (from Tune's record)
    assert finished and all(
        json.loads((p / "status.json").read_text())["steps"] == 192 for p in finished
    )  # the others ran to the end

    assert main(["plot", str(root)]) == 0
    assert (root / "learning-curves.png").is_file()
    from parallel_eplus.experiments.sweep_curves import curves

    data, source = curves(root)
    assert source == "evaluations" and set(data["recipe"]) == {"residual_scale=0", "residual_scale=0.2"}
    assert data.groupby("recipe")["seed"].nunique().to_dict() == {"residual_scale=0": 2, "residual_scale=0.2": 2}


def _show(capsys, name: str) -> list[str]:
    assert main(["runs", "show", name]) == 0
    return capsys.readouterr().out.splitlines()


@pytest.mark.slow
def test_pbt_continues_the_trailing_trial_from_the_leaders_weights_with_perturbed_settings(tmp_path, monkeypatch,
                                                                                         capsys, no_leaks):  # fmt: skip
    monkeypatch.chdir(tmp_path)
    spec = write_spec(
        tmp_path,
        f"""name = "pbt"
seeds = [0, 1]
{BASE.format(timesteps=192)}
[scheduler]
type = "pbt"
interval = 96
quantile_fraction = 0.5
[scheduler.mutations]
"trpo.target_kl" = [0.005, 0.02]
""",
    )
    assert main(["sweep", str(spec)]) == 0
    root = tmp_path / "runs" / "pbt"
    exploited = [p for p in root.glob("seed-*") if (p / "pbt.json").is_file()]
    assert exploited, capsys.readouterr().out
    # synchronous PBT: both trials report at 96 steps, the trailing one is replaced then and trains on to 192
    for run in exploited:  # it continued from the leader's save, with a target_kl PBT drew, to the planned steps
        last = json.loads((run / "pbt.json").read_text())[-1]
        donor_save = Path(last["from"])
        assert donor_save.parent.parent != run
        copy = run / "checkpoints" / f"model_{last['steps']}_steps.zip"
        assert filecmp.cmp(copy, donor_save, shallow=False) and last["steps"] < 192  # its save when PBT chose it
        config = json.loads((run / "config.json").read_text())
        assert config["trpo"]["target_kl"] in (0.005, 0.02) and last["settings"]["trpo"] == config["trpo"]
        assert json.loads((run / "status.json").read_text())["steps"] >= 192
