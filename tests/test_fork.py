"""Forked episodes (episodes/fork.py, fork_side.py): each episode forked from an EnergyPlus parked at its first step."""

from __future__ import annotations

import os
import re
import signal
import time
from pathlib import Path

import numpy as np
import pytest

from parallel_eplus import EnergyPlusEnv, EnergyPlusError
from parallel_eplus.engine.episodes import fork
from parallel_eplus.engine.episodes.fork import ForkedEpisode

from .conftest import our_processes
from .test_prepared import ZERO, _episode, _parked
from .test_prepared_faults import _state


def _forked(env: EnergyPlusEnv) -> bool:
    return isinstance(env.sim.process.proc, ForkedEpisode)


def _unstamped(path) -> bytes:
    """The file without the minute its EnergyPlus started (the .eio's first line ends `YMD=2026.11.28 01:07`): a fork's
    is its template's, and on a busy machine the cold run may start in the next minute."""
    return re.sub(rb"YMD=\d{4}\.\d{2}\.\d{2} \d{2}:\d{2}", b"YMD=", path.read_bytes(), count=1)


def _template(env: EnergyPlusEnv, weather: int = 0) -> fork.Template:
    """The env's template for its `weather`-th weather file, once parked."""
    t = env.sim.supply.templates.by_epw[env.sim.weather_paths[weather]]
    assert t.wait_parked()
    return t


@pytest.fixture(scope="module")
def cold(tmp_path_factory):
    """`cold(weather, n, building)`: what n episodes of a cold env (each in a process of its own, nothing prepared or
    forked) under the zero action give, and the folder they were written to. A cold env's episodes are the same
    whatever follows them, and without a random start or noisy weather each one is the same as the first: one runs
    per (weather, building) for the module, and stands for the n (a forked episode that differed from it fails)."""
    made: dict[tuple, tuple[np.ndarray, Path]] = {}

    def episodes(weather: str, n: int = 1, building: str | None = None) -> tuple[list[np.ndarray], Path]:
        key = (weather, building)
        if key not in made:
            out = tmp_path_factory.mktemp(f"cold-{weather}")
            env = EnergyPlusEnv(weather=weather, run_days=1, output_dir=out, prepare_next=False, building=building)
            try:
                assert not env.config.random_start and env.config.weather_noise is None
                made[key] = _episode(env), out
            finally:
                env.close()
        run, out = made[key]
        return [run] * n, out

    return episodes


@pytest.mark.slow
@pytest.mark.parametrize(("weather", "building"), [("CA", None), ("FL", None), ("CA", "office-small")])
def test_a_forked_episode_equals_a_cold_one_step_for_step(tmp_path, cold, no_leaks, weather, building):
    """The office's meters keep its steps in the Python bridge: forks hold there too."""
    expected, cold_out = cold(weather, 3, building)
    env = EnergyPlusEnv(weather=weather, run_days=1, output_dir=tmp_path / "forked", building=building)
    try:
        got = []
        for _ in range(3):
            obs, _ = env.reset()
            assert _forked(env)
            rows, terminated = [np.append(obs, 0.0)], False
            while not terminated:
                obs, reward, terminated, _, _ = env.step(np.zeros(env.action_space.shape, np.float32))
                rows.append(np.append(obs, reward))
            got.append(np.array(rows))
        template = _template(env)
        files = sorted(p.name for p in template.dir.iterdir())
    finally:
        env.close()
    for a, b in zip(expected, got, strict=True):
        np.testing.assert_array_equal(a, b)  # bit for bit: observations and rewards
    cold_dir = next(cold_out.glob("episode-000001-*"))
    for d in sorted((tmp_path / "forked").glob("episode-*")):  # the same files as a cold episode's, nothing more
        assert sorted(p.name for p in d.iterdir()) == sorted(p.name for p in cold_dir.iterdir())
        for name in ("eplusout.csv", "eplusout.eio"):  # EnergyPlus's own outputs too, where the model writes them
            if (cold_dir / name).exists():
                assert _unstamped(d / name) == _unstamped(cold_dir / name), name
    assert "eplusout.end" not in files  # what the children wrote later went to their own directories
    assert not template.dir.exists()  # removed with its process


@pytest.mark.slow
def test_every_episode_after_the_first_is_forked_and_prepared(tmp_path, no_leaks):
    env = EnergyPlusEnv(weather="CA", run_days=1, output_dir=tmp_path)
    try:
        kinds = []
        for _ in range(3):
            env.reset()
            kinds.append((_forked(env), env.sim._from_prepared))
            env.step(ZERO)  # the next is forked here, and parks at once
            assert isinstance(_parked(env).process.proc, ForkedEpisode)
        assert kinds == [(True, False), (True, True), (True, True)]
        assert env.sim.process.warm.proc is None and env.sim.supply.spare.warm.proc is None  # no long-lived process
    finally:
        env.close()


@pytest.mark.slow
def test_a_reset_for_another_weather_discards_what_was_prepared_and_forks_from_that_weathers_template(
    tmp_path, cold, no_leaks
):
    ca, fl = cold("CA")[0][0], cold("FL")[0][0]
    env = EnergyPlusEnv(weather=["CA", "FL"], run_days=1, output_dir=tmp_path / "forked")
    try:
        env.reset()
        env.step(ZERO)  # prepares FL (its template starts; until it parks, in a long-lived process)
        ready = _parked(env)
        assert ready.plan.weather == "FL"
        _template(env, 1)
        got = _episode(env, options={"weather_index": 0})  # CA again: not what was prepared
        assert _forked(env) and not env.sim._from_prepared and not ready.episode_dir.exists()
        np.testing.assert_array_equal(got, ca)
        got = _episode(env, options={"weather_index": 1})  # FL: what was prepared was CA (the rotation's next)
        assert _forked(env) and not env.sim._from_prepared
        np.testing.assert_array_equal(got, fl)
        ready = _parked(env)  # the rotation's next, FL, forked from FL's template
        assert ready.plan.weather == "FL" and isinstance(ready.process.proc, ForkedEpisode)
        np.testing.assert_array_equal(_episode(env), fl)
        assert _forked(env) and env.sim._from_prepared
        got = _episode(env, seed=5)  # a seed it was not planned for: forked afresh
        assert _forked(env) and not env.sim._from_prepared
        np.testing.assert_array_equal(got, ca)
        assert len(env.sim.supply.templates.by_epw) == 2  # one parked per weather file of the rotation
    finally:
        env.close()


def _gone(pids: list[int], timeout_s: float = 10.0) -> bool:
    deadline = time.monotonic() + timeout_s
    while any(_state(p) not in ("", "Z") for p in pids):
        if time.monotonic() > deadline:
            return False
        time.sleep(0.02)
    return True


@pytest.mark.slow
def test_a_template_killed_mid_episode_loses_no_episode_and_is_replaced(tmp_path, cold, no_leaks):
    expected = cold("CA", 4)[0]
    env = EnergyPlusEnv(weather="CA", run_days=1, output_dir=tmp_path / "forked")
    try:
        obs, _ = env.reset()
        rows = [np.append(obs, 0.0)]
        for _ in range(10):  # the next episode is forked at the first step
            obs, reward, terminated, _, _ = env.step(ZERO)
            rows.append(np.append(obs, reward))
        killed = _template(env)
        os.kill(killed.proc.pid, signal.SIGKILL)  # its children are episodes of their own: they run on
        while not terminated:
            obs, reward, terminated, _, _ = env.step(ZERO)
            rows.append(np.append(obs, reward))
        got = [np.array(rows), _episode(env)]  # the second: forked before the kill
        assert _template(env).proc.pid != killed.proc.pid and not killed.dir.exists()  # replaced at its first step
        got += [_episode(env), _episode(env)]  # the third started in a long-lived process (the new one was parking)
        assert env.sim._from_prepared and _forked(env)  # the fourth forked from the new template
    finally:
        env.close()
    for a, b in zip(expected, got, strict=True):
        np.testing.assert_array_equal(a, b)
    assert our_processes() == []


@pytest.mark.slow
def test_a_forked_episode_killed_mid_episode_raises_promptly_and_the_env_recovers(tmp_path, cold, no_leaks):
    expected = cold("CA")[0][0]
    env = EnergyPlusEnv(weather="CA", run_days=1, output_dir=tmp_path / "forked")
    try:
        env.reset()
        for _ in range(10):
            env.step(ZERO)
        child, prepared = env.sim.proc.pid, env.sim.prepared.process.proc.pid
        template = _template(env).proc.pid
        os.kill(child, signal.SIGKILL)
        t0 = time.monotonic()
        with pytest.raises(EnergyPlusError, match="died"):
            for _ in range(5):
                env.step(ZERO)
        assert time.monotonic() - t0 < 5
        assert _gone([child, prepared, template])  # an error ends the worker's processes: it starts afresh
        np.testing.assert_array_equal(_episode(env), expected)
        assert _forked(env)
    finally:
        env.close()


@pytest.mark.slow
def test_a_hung_template_is_replaced_and_the_episode_starts_without_it(tmp_path, cold, no_leaks, monkeypatch):
    expected = cold("CA", 3)[0]
    monkeypatch.setattr(fork, "ANSWER_S", 1.0)
    env = EnergyPlusEnv(weather="CA", run_days=1, output_dir=tmp_path / "forked")
    try:
        obs, _ = env.reset()
        rows, terminated = [np.append(obs, 0.0)], False
        hung = _template(env)
        os.kill(hung.proc.pid, signal.SIGSTOP)  # its running child is an episode of its own: it runs on
        while not terminated:  # the next episode is asked of it here, without waiting: it never answers
            obs, reward, terminated, _, _ = env.step(ZERO)
            rows.append(np.append(obs, reward))
        t0 = time.monotonic()
        got = [np.array(rows), _episode(env)]  # no answer within 1 s: started from a new template
        assert time.monotonic() - t0 < 60
        assert _forked(env) and not env.sim._from_prepared
        assert _template(env).proc.pid != hung.proc.pid and _gone([hung.proc.pid]) and not hung.dir.exists()
        got.append(_episode(env))
        assert _forked(env) and env.sim._from_prepared
    finally:
        env.close()
    for a, b in zip(expected, got, strict=True):
        np.testing.assert_array_equal(a, b)


@pytest.mark.slow
def test_a_forked_episode_killed_while_parked_is_replaced(tmp_path, cold, no_leaks):
    expected = cold("CA", 2)[0]
    env = EnergyPlusEnv(weather="CA", run_days=1, output_dir=tmp_path / "forked")
    try:
        obs, _ = env.reset()
        rows, terminated = [np.append(obs, 0.0)], False
        while not terminated:
            obs, reward, terminated, _, _ = env.step(ZERO)
            rows.append(np.append(obs, reward))
            if env.sim.prepared is not None and len(rows) == 2:
                struck = _parked(env)
                os.kill(struck.process.proc.pid, signal.SIGKILL)
        again = _episode(env)
        assert _forked(env) and not env.sim._from_prepared  # forked afresh, not handed out
        assert not struck.episode_dir.exists()
    finally:
        env.close()
    np.testing.assert_array_equal(np.array(rows), expected[0])
    np.testing.assert_array_equal(again, expected[1])


@pytest.mark.slow
def test_close_ends_the_templates_and_their_children_and_removes_their_directories(tmp_path, no_leaks):
    env = EnergyPlusEnv(weather=["CA", "FL"], run_days=1, output_dir=tmp_path)
    try:
        env.reset()
        env.step(ZERO)
        _template(env, 1)
        _episode(env)  # FL (prepared before FL's template parked)
        env.reset()
        while env.sim.prepared is None:  # CA's successor (FL) is forked once the process before has finished
            env.step(ZERO)
        templates = list(env.sim.supply.templates.by_epw.values())
        pids = [env.sim.proc.pid, _parked(env).process.proc.pid, *(t.proc.pid for t in templates)]
    finally:
        env.close()
    assert len(templates) == 2 and _gone(pids, timeout_s=0.5)  # at once: nothing waited for
    assert not any(t.dir.exists() for t in templates)
