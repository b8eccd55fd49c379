"""Soak: 100 one-day episodes in one process (a 2-worker vector env, then 16 single envs open at once).

Open file descriptors, EnergyPlus processes, pipe directories and resident memory must stay flat: a leak
of one descriptor or pipe per episode would show as +50 by the end. The figures are printed (-s) and
quoted in docs/reliability.md.
"""

from __future__ import annotations

import os
import tempfile
import time
from pathlib import Path

import numpy as np
import pytest

from parallel_eplus import EnergyPlusEnv
from parallel_eplus.engine.config import SimulationConfig
from parallel_eplus.envs.vector_env import EnergyPlusVectorEnv

from ..conftest import our_processes

VECTOR_EPISODES, SINGLE_EPISODES, SINGLE_ENVS = 50, 50, 16


def _sample(episodes: int) -> dict:
    status = Path("/proc/self/status").read_text()
    rss_kb = int(next(ln for ln in status.splitlines() if ln.startswith("VmRSS:")).split()[1])
    pipes = [d for d in os.listdir(tempfile.gettempdir()) if d.startswith(f"parallel-eplus-{os.getpid()}-")]
    return {
        "episodes": episodes, "fds": len(os.listdir("/proc/self/fd")), "processes": len(our_processes()),
        "pipes": len(pipes), "rss_mb": rss_kb / 1024,
    }  # fmt: skip


def _report(title: str, samples: list[dict]) -> None:
    print(f"\n{title}")
    print("episodes   fds  EnergyPlus processes  pipe dirs  RSS (MB)")
    for s in samples:
        print(f"{s['episodes']:8d} {s['fds']:5d} {s['processes']:21d} {s['pipes']:10d} {s['rss_mb']:9.1f}")


def _assert_flat(samples: list[dict], max_processes: int, pipes: int) -> None:
    """Flat once every env has made its pipes (each makes them at its first episode)."""
    warm = next(s for s in samples if s["episodes"] >= pipes)
    for s in samples[1:]:
        assert s["processes"] <= max_processes and s["pipes"] == min(s["episodes"], pipes), samples
        if s["episodes"] >= warm["episodes"]:
            assert s["fds"] <= warm["fds"] + 2, samples
    assert samples[-1]["rss_mb"] - warm["rss_mb"] < 40, samples


@pytest.mark.slow
def test_soak_100_episodes_leave_descriptors_processes_pipes_and_memory_flat(tmp_path, no_leaks):
    t0 = time.monotonic()
    start = _sample(0)

    venv = EnergyPlusVectorEnv(SimulationConfig(run_days=1, output_dir=str(tmp_path / "v"), keep_episodes=1),
                               [["CA"], ["FL"]])  # fmt: skip
    vector = [start]
    try:
        venv.reset(seed=0)
        done = 0
        while done < VECTOR_EPISODES:
            _, _, terminated, truncated, _ = venv.step(np.zeros((2, 4), dtype=np.float32))
            assert not truncated.any()
            if terminated.any():
                done += int(terminated.sum())
                if done % 10 == 0 or done == 2:
                    vector.append(_sample(done))
    finally:
        venv.close()
    vector.append({**_sample(done), "episodes": -1})  # after close
    _report("2-worker vector env (-1: after close)", vector)
    _assert_flat(vector[:-1], max_processes=2, pipes=2)

    envs = [EnergyPlusEnv(weather="CO", run_days=1, output_dir=tmp_path / f"s{i}", keep_episodes=1)
            for i in range(SINGLE_ENVS)]  # fmt: skip
    single = [_sample(0)]
    try:
        for k in range(SINGLE_EPISODES):
            env = envs[k % SINGLE_ENVS]
            env.reset(seed=k)
            terminated = False
            while not terminated:
                _, _, terminated, truncated, _ = env.step(np.zeros(4, dtype=np.float32))
                assert not truncated
            if (k + 1) % 10 == 0 or k == 1:
                single.append(_sample(k + 1))
    finally:
        for env in envs:
            env.close()
    single.append({**_sample(SINGLE_EPISODES), "episodes": -1})
    _report(f"{SINGLE_ENVS} single envs in one process (-1: after close)", single)
    _assert_flat(single[:-1], max_processes=1, pipes=SINGLE_ENVS)

    end = single[-1]
    assert end["fds"] <= start["fds"] + 2 and end["processes"] == 0 and end["pipes"] == 0
    print(f"\n100 episodes in {time.monotonic() - t0:.0f} s; fds {start['fds']} -> {end['fds']}, "
          f"RSS {start['rss_mb']:.0f} -> {end['rss_mb']:.0f} MB")  # fmt: skip
