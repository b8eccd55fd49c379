"""`train --random-start`: each episode from a day of the year drawn for it, so training sees every season."""

from __future__ import annotations

import datetime as dt

import numpy as np

from parallel_eplus.buildings.idf.prepare import _run_period, idf_objects
from parallel_eplus.engine.config import SimulationConfig
from parallel_eplus.engine.setup import WorkerSetup
from parallel_eplus.envs.vector_env import EnergyPlusVectorEnv


def test_episodes_start_on_drawn_days_prepared_as_drawn_on_the_models_weekdays(tmp_path, no_leaks):
    cfg = SimulationConfig(weather="CA", run_days=1, random_start=True, seed=7, output_dir=str(tmp_path))
    setup = WorkerSetup.resolve(cfg, ["CA"])
    venv = EnergyPlusVectorEnv(cfg, [["CA"], ["CA"]])
    action = [np.zeros(4, np.float32)] * 2
    firsts: list[list[dt.datetime]] = [[], []]
    try:
        infos = venv.start_all([0, 1])
        for episode in range(3):
            for i in range(2):
                firsts[i].append(infos[i]["time"])
            done = False
            while not done:  # a day of 96 steps; the next episode (prepared meanwhile) starts at the last
                _, _, dones, _, infos = venv.step_lists(action)
                done = bool(dones[0])
            assert all(dones)
            if episode > 0:  # the prepared episode was the one asked for: its plan drew the same day
                assert all(sim._from_prepared for sim in venv.sims)
    finally:
        venv.close()
    for i, sim in enumerate(venv.sims):
        expected = [setup.start_day(sim.name, n) for n in (1, 2, 3)]
        assert [t.timetuple().tm_yday for t in firsts[i]] == expected, (firsts[i], expected)
    days = {t.timetuple().tm_yday for ts in firsts for t in ts}
    assert len(days) >= 4  # six episodes, drawn over 365 days: the workers do not repeat each other
    # The model's January 1 is a Tuesday (2013's): a run cut from the year starts on that date's weekday
    assert all(t.year == 2013 for ts in firsts for t in ts)


def test_a_run_period_cut_from_the_year_keeps_the_models_weekdays():
    text = "RunPeriod, Year, 1, 1, , 12, 31, , Tuesday, Yes, Yes, No, Yes, Yes;"
    first = idf_objects(text)[0]
    march = idf_objects(_run_period(first, 14, 65))[0]  # day 65: March 6, 2013, a Wednesday
    assert march.fields[1:3] == ["3", "6"] and march.fields[7] == "Wednesday"
    assert idf_objects(_run_period(first, 14, 65, "Monday"))[0].fields[7] == "Monday"  # a test period's own
    assert idf_objects(_run_period(first, 14, 1))[0].fields[7] == "Tuesday"


def test_train_random_start_records_each_episodes_day(tmp_path, no_leaks):
    import pandas as pd

    from parallel_eplus.training.config import TrainConfig
    from parallel_eplus.training.train import train

    cfg = TrainConfig(workers=2, weathers=["CA", "FL"], run_days=1, random_start=True, timesteps=384, batch_size=192,
                      seed=3, run_name="seasons", runs_dir=str(tmp_path / "runs"),
                      tensorboard_dir=str(tmp_path / "tb"))  # fmt: skip
    train(cfg, progress=False)
    episodes = pd.read_csv(tmp_path / "runs/seasons/episodes.csv")
    assert len(episodes) == 4 and episodes["start_day"].between(1, 365).all()
    assert episodes["start_day"].nunique() >= 3
    assert TrainConfig.from_json((tmp_path / "runs/seasons/config.json").read_text()).random_start  # kept for --resume
