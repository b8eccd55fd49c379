"""Prepared episodes (engine/episodes/prepared.py): the next episode started while one runs, swapped in by `reset()`."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

from parallel_eplus import EnergyPlusEnv

ZERO = np.zeros(4, dtype=np.float32)


def _episode(env: EnergyPlusEnv, **reset) -> np.ndarray:
    """One whole episode under a constant action: every observation and reward, row by row."""
    obs, _ = env.reset(**reset)
    rows, terminated = [np.append(obs, 0.0)], False
    while not terminated:
        obs, reward, terminated, truncated, _ = env.step(np.zeros(env.action_space.shape, np.float32))
        assert not truncated
        rows.append(np.append(obs, reward))
    return np.array(rows)


def _parked(env: EnergyPlusEnv, timeout_s: float = 120.0):
    """The env's prepared episode, once it waits at its first control step."""
    deadline = time.monotonic() + timeout_s
    while env.sim.prepared is None or not env.sim.prepared.parked():
        assert time.monotonic() < deadline, "the next episode was not prepared"
        time.sleep(0.02)
    return env.sim.prepared


@pytest.fixture(scope="module")
def cold_rotation(tmp_path_factory) -> list[np.ndarray]:
    """Three episodes of a cold env (each in a process of its own, nothing prepared) rotating CA, FL: the reference
    both kinds of prepared episode are held to."""
    cold = EnergyPlusEnv(weather=["CA", "FL"], run_days=1, output_dir=tmp_path_factory.mktemp("cold"),
                         prepare_next=False)  # fmt: skip
    try:
        return [_episode(cold) for _ in range(3)]
    finally:
        cold.close()


@pytest.mark.slow
@pytest.mark.parametrize("fork", [False, True], ids=["long-lived", "forked"])
def test_a_prepared_episode_equals_a_cold_one_step_for_step(tmp_path, cold_rotation, no_leaks, fork):
    weathers = ["CA", "FL"]
    warm = EnergyPlusEnv(weather=weathers, run_days=1, output_dir=tmp_path / "warm", fork_episodes=fork)
    try:
        expected = cold_rotation
        got, prepared = [], []
        for _ in range(3):
            got.append(_episode(warm))
            prepared.append(warm.sim._from_prepared)
    finally:
        warm.close()
    assert prepared == [False, True, True]  # the first reset has nothing prepared
    for a, b in zip(expected, got, strict=True):
        np.testing.assert_array_equal(a, b)  # bit for bit: observations and rewards
    assert sorted(p.name for p in (tmp_path / "warm").iterdir()) == [
        "episode-000001-CA", "episode-000002-FL", "episode-000003-CA"
    ]  # fmt: skip


@pytest.mark.slow
def test_a_reset_with_other_options_or_a_seed_discards_the_prepared_episode(tmp_path, no_leaks):
    env = EnergyPlusEnv(weather=["CA", "FL"], run_days=1, output_dir=tmp_path, fork_episodes=False)
    try:
        env.reset()
        env.step(ZERO)  # the first action starts preparing the next episode (FL)
        ready = _parked(env)
        assert ready.plan.weather == "FL"
        pid = ready.process.proc.pid
        obs, info = env.reset(options={"weather_index": 0})  # CA again: not what was prepared
        assert not env.sim._from_prepared and info["weather"] == "CA"
        assert not ready.episode_dir.exists()  # discarded: its directory removed, its run over
        assert ready.process.proc is None and ready.process.warm.proc.pid == pid  # stopped, its process kept
        env.step(ZERO)
        ready = _parked(env)
        env.reset(seed=3)  # a seed the prepared episode was not planned for
        assert not env.sim._from_prepared and not ready.episode_dir.exists()
        env.step(ZERO)
        _parked(env)
        env.reset(options={"weather_index": env.sim.prepared.plan.weather_index})  # exactly what was prepared
        assert env.sim._from_prepared
    finally:
        env.close()


@pytest.mark.slow
def test_a_reset_mid_episode_stops_energyplus_and_keeps_its_process_and_the_partial_record(tmp_path, no_leaks):
    import json

    env = EnergyPlusEnv(weather="CA", run_days=1, output_dir=tmp_path, fork_episodes=False)
    try:
        env.reset()
        for _ in range(5):
            env.step(ZERO)
        cut, pid = env.episode_dir, env.sim.proc.pid
        warm = env.sim.process.warm
        env.reset()
        assert warm.proc is not None and warm.proc.pid == pid  # stopped by a control frame, not killed
        summary = json.loads((cut / "summary.json").read_text())
        assert summary["complete"] is False and summary["steps"] == 5
        _episode(env, options={"weather_index": 0})  # the same process serves a later episode
    finally:
        env.close()


@pytest.mark.slow
def test_a_prepared_episode_with_weather_noise_equals_a_cold_one(tmp_path, no_leaks):
    """The noise is drawn when the episode is prepared, from the same seed a cold start draws it from."""
    kw = {"weather": "CA", "run_days": 1, "weather_noise": "drybulb=1:0:24", "seed": 7}
    cold = EnergyPlusEnv(output_dir=tmp_path / "cold", prepare_next=False, **kw)
    warm = EnergyPlusEnv(output_dir=tmp_path / "warm", **kw)
    try:
        expected = [_episode(cold) for _ in range(2)]
        got = [_episode(warm) for _ in range(2)]
        assert warm.sim._from_prepared and warm.sim.supply.templates is None  # a new weather file each: no fork
    finally:
        cold.close()
        warm.close()
    for a, b in zip(expected, got, strict=True):
        np.testing.assert_array_equal(a, b)
    assert not np.array_equal(got[0][:, 0], got[1][:, 0])  # each episode its own perturbed outdoor temperature


@pytest.mark.slow
def test_a_prepared_episode_swapped_in_still_warming_up_starts_the_next_at_once(tmp_path, no_leaks):
    """Back to back: the spare process starts the episode after next at the reset, not at the first action."""
    env = EnergyPlusEnv(weather=["CA", "FL"], run_days=1, output_dir=tmp_path, fork_episodes=False)
    try:
        env.reset()
        obs, reward, terminated, _, _ = env.step(ZERO)  # the next episode (FL) starts preparing here
        ready = env.sim.prepared
        os.kill(ready.process.proc.pid, signal.SIGSTOP)  # held in its start-up: it cannot park before the reset
        while not terminated:
            obs, reward, terminated, _, _ = env.step(ZERO)
        env.sim.launch()  # reset()'s first half: swap it in, not yet parked
        assert env.sim._from_prepared and env.sim.process is ready.process
        after = env.sim.prepared
        assert after is not None and after.plan.weather == "CA"  # the one after it, already on its way
        os.kill(ready.process.proc.pid, signal.SIGCONT)
        env.sim.first_observation()
        assert env.sim.prepared is after  # the first action does not start another
        env.step(ZERO)
        assert env.sim.prepared is after
    finally:
        env.close()


def test_the_energyplus_side_imports_no_gymnasium():
    """It registers no env: Gymnasium would cost each EnergyPlus-side process ~50 ms of start-up."""
    from parallel_eplus import ENGINE_SIDE

    code = "import sys, parallel_eplus.engine.eplus_side.callback; print('gymnasium' in sys.modules)"
    for marked, expected in ((True, "False"), (False, "True")):
        env = {k: v for k, v in os.environ.items() if k != ENGINE_SIDE} | ({ENGINE_SIDE: "1"} if marked else {})
        out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True)
        assert out.stdout.strip() == expected
