"""The vector env over real EnergyPlus workers: stepping, autoreset, weather shares and crashes."""

from __future__ import annotations

import os
import signal

import numpy as np
import pytest

from parallel_eplus.errors import EnergyPlusError
from parallel_eplus.model import STEPS_PER_DAY
from parallel_eplus.simulation import SimulationConfig
from parallel_eplus.vector_env import EnergyPlusVectorEnv, weather_shares


def test_weather_shares():
    assert weather_shares(["CA"], 2) == [["CA"], ["CA"]]
    assert weather_shares(["CA", "CO", "FL"], 2) == [["CA", "FL"], ["CO"]]
    assert weather_shares(["CA", "CO"], 3) == [["CA"], ["CO"], ["CA"]]


def test_vector_env_autoresets_and_cycles_weathers(tmp_path, no_leaks):
    venv = EnergyPlusVectorEnv(SimulationConfig(run_days=1, output_dir=str(tmp_path)), [["CA", "FL"], ["CO"]])
    try:
        obs, info = venv.reset(seed=0)
        assert obs.shape == (2, 6) and list(info["weather"]) == ["CA", "CO"]
        for _ in range(STEPS_PER_DAY):
            obs, rewards, terminated, truncated, info = venv.step(np.zeros((2, 4), dtype=np.float32))
            assert np.isfinite(rewards).all() and not truncated.any()
        assert terminated.all()  # the day ended on both workers in the same step...
        assert info["final_info"]["episode_summary"]["weather"][0] == "CA"
        assert list(info["weather"]) == ["FL", "CO"]  # ...and the next episodes began: worker 0 cycles
        assert venv.observation_space.contains(obs)
    finally:
        venv.close()


def test_crashed_worker_restarts_its_episode_then_gives_up(tmp_path, no_leaks, caplog):
    venv = EnergyPlusVectorEnv(SimulationConfig(run_days=1, output_dir=str(tmp_path)), [["CA"], ["FL"]], max_restarts=1)
    try:
        venv.reset()
        for _ in range(3):
            venv.step_lists(np.zeros((2, 4)))
        os.kill(venv.sims[1].proc.pid, signal.SIGKILL)
        obs, rewards, terminated, truncated, infos = venv.step_lists(np.zeros((2, 4)))
        assert list(truncated) == [False, True] and not terminated.any()
        assert "energyplus_error" in infos[1] and "final_obs" in infos[1]
        assert "restarting its episode" in caplog.text
        assert infos[1]["weather"] == "FL" and infos[1]["time"].hour == 0  # the same weather, from the start
        venv.step_lists(np.zeros((2, 4)))  # worker 0 never noticed
        os.kill(venv.sims[1].proc.pid, signal.SIGKILL)
        with pytest.raises(EnergyPlusError, match="worker 1 failed 2 times in a row on weather FL"):
            venv.step_lists(np.zeros((2, 4)))
    finally:
        venv.close()


def test_out_of_bounds_observation_is_clipped_with_raw_value_in_info(tmp_path):
    from parallel_eplus.simulation import Simulation

    sim = Simulation(SimulationConfig(run_days=1, output_dir=str(tmp_path)))
    try:
        frame = np.array([2013, 1, 0, 15, 55.0, 23.0, 60.0, 1e5, 9e4, 1e4])  # 55 C outdoor, 60 C East zone
        obs, info = sim._observation(frame)
        assert obs[0] == 50.0 and obs[2] == 50.0
        assert info["raw_observation"][0] == 55.0 and info["east_temp_c"] == 60.0
    finally:
        sim.close()
