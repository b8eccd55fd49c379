"""Prepared episodes (engine/prepared.py): the next episode started while one runs, swapped in by `reset()`."""

from __future__ import annotations

import contextlib
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from parallel_eplus import EnergyPlusEnv
from parallel_eplus.buildings.resources import SOURCE_ROOT
from parallel_eplus.engine.pipe_sweep import sweep

from .conftest import our_processes

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


@pytest.mark.slow
@pytest.mark.parametrize("fork", [False, True], ids=["long-lived", "forked"])
def test_a_prepared_episode_equals_a_cold_one_step_for_step(tmp_path, no_leaks, fork):
    weathers = ["CA", "FL"]
    cold = EnergyPlusEnv(weather=weathers, run_days=1, output_dir=tmp_path / "cold", prepare_next=False)
    warm = EnergyPlusEnv(weather=weathers, run_days=1, output_dir=tmp_path / "warm", fork_episodes=fork)
    try:
        expected = [_episode(cold) for _ in range(3)]
        got, prepared = [], []
        for _ in range(3):
            got.append(_episode(warm))
            prepared.append(warm.sim._from_prepared)
    finally:
        cold.close()
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


def _state(pid: int) -> str:
    try:
        return open(f"/proc/{pid}/stat").read().rsplit(")", 1)[1].split()[0]
    except OSError:
        return ""


def test_a_process_whose_main_thread_is_gone_is_not_handed_out():
    """Killed while its other threads still exit: not reapable yet (`poll()` says running), but never to step."""
    from parallel_eplus.engine.prepared import _exiting

    code = "import ctypes, threading, time; threading.Thread(target=time.sleep, args=(30,)).start(); " \
           "ctypes.CDLL(None).pthread_exit(None)"  # fmt: skip
    proc = subprocess.Popen([sys.executable, "-c", code])
    try:
        assert not _exiting(None)
        deadline = time.monotonic() + 10
        while not _exiting(proc.pid):
            assert time.monotonic() < deadline, _state(proc.pid)
            time.sleep(0.01)
        assert proc.poll() is None and _state(proc.pid) == "Z"
    finally:
        proc.kill()
        proc.wait()
    assert not _exiting(proc.pid)  # reaped: gone


def test_a_long_lived_process_still_tearing_down_is_not_usable(tmp_path):
    """The path a reset takes (`usable` -> `Episode.poll`), deterministically: a killed process whose main thread is
    gone while another still exits holds its stdout open (no EOF) and is not reapable (`poll()` None), so only its
    main thread's state says it will never step. Under load this lasted tens of ms: the intermittent failure."""
    from parallel_eplus.engine.prepared import EpisodePlan, PreparedEpisode
    from parallel_eplus.engine.process import EnergyPlusProcess
    from parallel_eplus.engine.warm_process import Episode

    code = "import ctypes, threading, time; threading.Thread(target=time.sleep, args=(30,)).start(); " \
           "ctypes.CDLL(None).pthread_exit(None)"  # fmt: skip
    process = EnergyPlusProcess(0.0, None, warm=True)
    warm = process.warm
    warm.proc = subprocess.Popen([sys.executable, "-c", code], stdin=subprocess.PIPE, stdout=subprocess.PIPE)
    os.set_blocking(warm.proc.stdout.fileno(), False)
    process.proc = Episode(warm)  # as `spawn` leaves it: the episode's answer awaited on the process's stdout
    ready = PreparedEpisode(EpisodePlan(0, "CA", tmp_path / "CA.epw"), process, tmp_path, 1)
    try:
        deadline = time.monotonic() + 10
        while _state(warm.proc.pid) != "Z":
            assert time.monotonic() < deadline, _state(warm.proc.pid)
            time.sleep(0.01)
        assert process.running()  # no EOF, not reapable: poll() alone says alive
        assert not ready.usable(60.0)
    finally:
        process.close()
    assert warm.proc is None


@pytest.mark.slow
@pytest.mark.parametrize("fault", ["killed", "hung"])
def test_a_dead_or_hung_prepared_process_is_replaced_and_leaves_nothing(tmp_path, no_leaks, fault):
    env = EnergyPlusEnv(weather="CA", run_days=1, output_dir=tmp_path, fork_episodes=False)  # forks: test_fork.py
    try:
        obs, _ = env.reset()
        rows = [np.append(obs, 0.0)]
        obs, reward, terminated, _, _ = env.step(ZERO)  # the next episode starts preparing here
        rows.append(np.append(obs, reward))
        ready = env.sim.prepared
        pid = ready.process.proc.pid
        if fault == "killed":  # died while parked at its first step
            _parked(env)
            os.kill(pid, signal.SIGKILL)
            # A kill is asynchronous: once its main thread is gone ("Z"), it must not be handed out, though its other
            # threads may still be exiting (not reapable yet) with its observation 0 still in the pipe.
            deadline = time.monotonic() + 10
            while _state(pid) not in ("", "Z"):
                assert time.monotonic() < deadline, f"the killed process {pid} did not exit: {_state(pid)}"
                time.sleep(0.005)
        else:  # stopped in its start-up, and now past its deadline
            os.kill(pid, signal.SIGSTOP)
            ready.process.deadline = time.monotonic() - 1
        while not terminated:
            obs, reward, terminated, _, _ = env.step(ZERO)
            rows.append(np.append(obs, reward))
        again = _episode(env)
        assert not env.sim._from_prepared  # replaced by a fresh start, not returned
        np.testing.assert_array_equal(np.array(rows), again)
        assert not ready.episode_dir.exists() and _state(pid) in ("", "Z")
    finally:
        env.close()
    assert our_processes() == []


WORKLOAD = """
import sys, time, numpy as np
from parallel_eplus import EnergyPlusEnv
env = EnergyPlusEnv(weather="CA", run_days=1, output_dir=sys.argv[1], fork_episodes=sys.argv[2] == "fork")
env.reset(); env.step(np.zeros(4, np.float32))
while env.sim.prepared is None or not env.sim.prepared.parked():
    time.sleep(0.02)
templates = [t.proc.pid for t in (env.sim.supply.templates.by_epw.values() if env.sim.supply.templates else ())]
print(env.sim.process.proc.pid, env.sim.prepared.process.proc.pid, *templates, flush=True)
time.sleep(60)
"""


def _as_from_a_shell() -> None:
    """The learner starts as a user's shell starts it: Ctrl-C delivered and handled by Python. A child inherits a
    blocked or ignored SIGINT from the test process, which tests before this one may have left so."""
    signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT})
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def _signal_state(pid: int) -> str:
    with contextlib.suppress(OSError):
        status = Path(f"/proc/{pid}/status").read_text().splitlines()
        return "; ".join(line for line in status if line.startswith(("State", "SigBlk", "SigIgn", "SigCgt")))
    return "gone"


@pytest.mark.slow
@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM, signal.SIGKILL])
@pytest.mark.parametrize("mode", ["fork", "long-lived"])
def test_the_learner_interrupted_or_killed_ends_running_and_prepared_processes(tmp_path, sig, mode):
    """The running and the prepared episode's processes end, and with forks their template (its children's parent)."""
    learner = subprocess.Popen([sys.executable, "-c", WORKLOAD, str(tmp_path), mode], cwd=SOURCE_ROOT,
                               stdout=subprocess.PIPE, text=True, preexec_fn=_as_from_a_shell)  # fmt: skip
    try:
        pids = [int(p) for p in learner.stdout.readline().split()]
        assert len(pids) == (3 if mode == "fork" else 2)
        learner.send_signal(sig)
        try:
            learner.wait(timeout=30)
        except subprocess.TimeoutExpired:
            state = _signal_state(learner.pid)
            raise AssertionError(f"the learner did not exit within 30 s of {sig!r}: {state}") from None
        deadline = time.monotonic() + 30
        while any(_state(p) not in ("", "Z") for p in pids):
            assert time.monotonic() < deadline, f"EnergyPlus-side processes outlived the learner: {pids}"
            time.sleep(0.05)
        if sig == signal.SIGINT:  # an uncaught Ctrl-C closes the env at exit: the episode so far is kept
            assert list(tmp_path.rglob("steps.parquet")), sorted(tmp_path.rglob("*"))
    finally:
        if learner.poll() is None:
            learner.kill()
            learner.wait()
        sweep()  # a killed learner's pipe directories: what its next run's first pipe sweeps


@pytest.mark.slow
def test_a_vector_env_worker_whose_prepared_process_died_starts_its_next_episode_afresh(tmp_path, no_leaks):
    from parallel_eplus.engine.config import SimulationConfig
    from parallel_eplus.envs.vector_env import EnergyPlusVectorEnv

    venv = EnergyPlusVectorEnv(SimulationConfig(run_days=1, output_dir=str(tmp_path)), [["CA"], ["FL"]])
    actions = np.zeros((2, 4), dtype=np.float32)
    try:
        venv.reset(seed=0)
        venv.step(actions)
        sim = venv.sims[0]
        deadline = time.monotonic() + 120
        while sim.prepared is None or not sim.prepared.parked():
            assert time.monotonic() < deadline
            time.sleep(0.02)
        struck = sim.prepared
        os.kill(struck.process.proc.pid, signal.SIGKILL)
        ended = np.zeros(2, int)
        while ended.min() < 2:
            _, _, terminated, truncated, _ = venv.step(actions)
            assert not truncated.any()  # replaced before it was handed out: no episode failed
            ended += terminated
    finally:
        venv.close()
    assert not struck.episode_dir.exists()  # what it prepared is gone; both episodes that ran are whole
    done = sorted((tmp_path / "worker-0").glob("episode-*"))
    assert struck.episode_dir not in done and len(done) == 2 and all((d / "steps.parquet").is_file() for d in done)


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

    code = "import sys, parallel_eplus.engine.eplus_callback; print('gymnasium' in sys.modules)"
    for marked, expected in ((True, "False"), (False, "True")):
        env = {k: v for k, v in os.environ.items() if k != ENGINE_SIDE} | ({ENGINE_SIDE: "1"} if marked else {})
        out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True)
        assert out.stdout.strip() == expected
