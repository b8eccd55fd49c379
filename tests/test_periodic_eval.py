"""Evaluation during training (`train --eval-every`): real short runs, 2 workers, one-day episodes."""

from __future__ import annotations

import json
import zipfile
from pathlib import Path

import pandas as pd
import pytest
from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

from parallel_eplus.evaluation.controllers import policy_controller
from parallel_eplus.evaluation.sweep import run_sweep
from parallel_eplus.runs.registry import read_run
from parallel_eplus.training.config import TrainConfig
from parallel_eplus.training.eval_target import EvalSettings, meets, parse_target, score
from parallel_eplus.training.train import train


def config(tmp_path: Path, name: str, timesteps: int, **evaluation) -> TrainConfig:
    return TrainConfig(
        workers=2, weathers=["CA", "FL"], run_days=1, timesteps=timesteps, batch_size=192, seed=0, run_name=name,
        runs_dir=str(tmp_path / "runs"), tensorboard_dir=str(tmp_path / "tb"), checkpoint_every=192,
        evaluation=EvalSettings(**evaluation),
    )  # fmt: skip


def steps_of(model_zip: Path) -> int:
    with zipfile.ZipFile(model_zip) as z:
        return int(json.loads(z.read("data"))["num_timesteps"])


@pytest.mark.parametrize(
    "settings, message",
    [
        (EvalSettings(every=192, weathers=["CA", "IL"]), "held out"),
        (EvalSettings(every=192, weathers=["va"]), "held out"),
        (EvalSettings(every=0, target="in_band_pct>=99"), "--eval-every"),
        (EvalSettings(every=192, target="in band >= 99"), "KPI>=VALUE"),
        (EvalSettings(every=-1), ">= 0"),
        (EvalSettings(every=192, scenarios=["summer"]), "--eval-scenarios summer"),
    ],
)
def test_bad_evaluation_settings_are_refused_before_anything_runs(tmp_path, settings, message):
    cfg = config(tmp_path, "bad", 192)
    cfg.evaluation = settings
    with pytest.raises(ValueError, match=message):
        cfg.resolved()


def test_best_is_met_then_lowest_energy_else_closest_or_highest_reward():
    terms = parse_target("in_band_pct>=99,energy_change_pct<=-10")
    met_low = {"in_band_pct": 99.5, "energy_change_pct": -20, "reward_mean": 0.1}
    met_high = {"in_band_pct": 100, "energy_change_pct": -11, "reward_mean": 0.9}
    missed_close = {"in_band_pct": 98.9, "energy_change_pct": -30, "reward_mean": 1.0}
    missed_far = {"in_band_pct": 50, "energy_change_pct": -40, "reward_mean": 2.0}
    assert meets(met_low, terms) and not meets(missed_close, terms)
    ranked = sorted([missed_far, met_high, missed_close, met_low], key=lambda k: score(k, terms), reverse=True)
    assert ranked == [met_low, met_high, missed_close, missed_far]
    assert score(missed_far, []) > score(met_low, [])  # no target: the mean reward decides


@pytest.mark.slow
def test_eval_every_writes_evaluations_at_batch_boundaries_and_keeps_the_best(tmp_path, no_leaks):
    # every 250 steps, batches of 192: due at the first boundary at or after 250 and 500 (384, 576)
    cfg = config(tmp_path, "ev", 576, every=250, days=1, target="in_band_pct>=0,energy_change_pct<=1000")
    train(cfg, progress=False)
    run = tmp_path / "runs" / "ev"
    table = pd.read_csv(run / "evaluations.csv")
    assert sorted(set(table["timesteps"])) == [384, 576]
    assert set(table["weather"]) == {"all", "CA", "FL"}
    means = table[table["weather"] == "all"].set_index("timesteps")
    per_weather = table[table["weather"] != "all"].groupby("timesteps")["in_band_pct"].mean()
    assert (means["in_band_pct"] - per_weather).abs().max() < 1e-9  # the means row is over the weathers
    events = EventAccumulator(str(tmp_path / "tb" / "ev"), size_guidance={"scalars": 0})
    events.Reload()
    assert [e.step for e in events.Scalars("eval/in_band_pct")] == [384, 576]  # TensorBoard, at the same steps
    assert [e.value for e in events.Scalars("eval/in_band_pct")] == pytest.approx(list(means["in_band_pct"]))
    assert "eval/FL/energy_change_pct" in events.Tags()["scalars"]
    base = json.loads((run / "eval_baseline.json").read_text())
    assert set(base) == {"CA|1", "FL|1"}  # the built-in controller ran once per weather, cached

    best_step = int(means["score"].idxmax())
    assert steps_of(run / "best" / "model.zip") == best_step
    assert (run / "best" / "vecnormalize.npz").is_file()
    # the best policy, evaluated by `evaluate`'s own sweep, gives the figures recorded at its step
    again = run_sweep([policy_controller(str(run / "best" / "model.zip"))], ["CA", "FL"], 1, 2, tmp_path / "again",
                      progress=False)  # fmt: skip
    recorded = table[(table["timesteps"] == best_step) & (table["weather"] != "all")].set_index("weather")
    for _, row in again.iterrows():
        assert row["in_band_pct"] == pytest.approx(recorded.loc[row["weather"], "in_band_pct"])
        assert row["power_kw"] == pytest.approx(recorded.loc[row["weather"], "power_kw"], rel=1e-6)

    target = json.loads((run / "target.json").read_text())  # met at the first evaluation
    assert target["timesteps"] == 384 and target["wall_s"] > 0
    info = read_run(run)
    assert info.evaluation["timesteps"] == 576 and info.target["timesteps"] == 384

    # resumed: the evaluations and the best are kept, and evaluation goes on from where it was
    train(config(tmp_path, "ev", 768, every=250, days=1, target=cfg.evaluation.target), resume=run, progress=False)
    table = pd.read_csv(run / "evaluations.csv")
    assert sorted(set(table["timesteps"])) == [384, 576, 768]
    means = table[table["weather"] == "all"].set_index("timesteps")
    assert steps_of(run / "best" / "model.zip") == int(means["score"].idxmax())
    assert json.loads((run / "target.json").read_text())["timesteps"] == 384


@pytest.mark.slow
def test_evaluation_periods_can_cover_the_seasons_and_a_target_not_met_is_not_recorded(tmp_path, no_leaks):
    """`--eval-scenarios start,peak_cool`: each weather's January days and BOPTEST's peak-cooling fortnight, the
    figures their mean, the built-in controls run once per period; a controller chosen in winter meets summer too.
    Its target cannot be met: it is not recorded, and the best so far is kept all the same."""
    cfg = config(tmp_path, "seasons", 192, every=192, weathers=["CA"], scenarios=["start", "peak_cool"],
                 target="in_band_pct>=101")  # fmt: skip
    train(cfg, progress=False)
    run = tmp_path / "runs" / "seasons"
    table = pd.read_csv(run / "evaluations.csv")
    assert set(table["weather"]) == {"all", "CA", "CA peak_cool"}
    rows = table.set_index("weather")
    assert rows.loc["CA", "energy_kwh"] < rows.loc["CA peak_cool", "energy_kwh"] / 10  # a day against two weeks
    assert rows.loc["all", "in_band_pct"] == pytest.approx(rows.loc[["CA", "CA peak_cool"], "in_band_pct"].mean())
    assert set(json.loads((run / "eval_baseline.json").read_text())) == {"CA|1", "CA|1|peak_cool"}
    periods = json.loads((run / "eval-periods" / "scenarios.json").read_text())
    assert periods["CA"]["peak_cool"]["start_day"] > 150  # summer

    assert list(table["timesteps"].unique()) == [192] and not table["target_met"].any()
    assert not (run / "target.json").exists()
    assert (run / "best" / "model.zip").is_file()  # the best so far is kept whether or not it meets the target
