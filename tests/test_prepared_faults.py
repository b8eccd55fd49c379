"""Prepared episodes that fail: a process killed, hung or half torn down is never handed out, and a learner
interrupted or killed leaves no EnergyPlus-side process behind."""

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
from parallel_eplus.engine.pipes.leftovers import sweep

from .conftest import our_processes
from .test_prepared import ZERO, _episode, _parked


def _state(pid: int) -> str:
    try:
        return open(f"/proc/{pid}/stat").read().rsplit(")", 1)[1].split()[0]
    except OSError:
        return ""


def test_a_process_whose_main_thread_is_gone_is_not_handed_out():
    """Killed while its other threads still exit: not reapable yet (`poll()` says running), but never to step."""
    from parallel_eplus.engine.episodes.prepared import _exiting

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
    from parallel_eplus.engine.episode import EpisodePlan
    from parallel_eplus.engine.episodes.prepared import PreparedEpisode
    from parallel_eplus.engine.episodes.process import EnergyPlusProcess
    from parallel_eplus.engine.episodes.warm import Episode

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
