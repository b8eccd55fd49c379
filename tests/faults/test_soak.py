"""Soak: 100 one-day episodes in one process (a 2-worker vector env, then 16 single envs open at once).

Open file descriptors, EnergyPlus processes, pipe directories and resident memory must stay flat: a leak
of one descriptor or pipe per episode would show as +50 by the end. The figures are printed (-s) and
quoted in docs/reliability.md. The episodes run in a fresh interpreter (soak_workload.py): in pytest's own
process, earlier tests' libraries (Ray's gRPC threads) open and close descriptors of their own meanwhile.
"""

from __future__ import annotations

import json
import subprocess
import sys
import time

import pytest

from parallel_eplus.buildings.resources import SOURCE_ROOT

from .soak_workload import PREPARED_EVERY, SINGLE_ENVS


def _report(title: str, samples: list[dict]) -> None:
    print(f"\n{title}")
    print("episodes   fds  EnergyPlus processes  pipe dirs  RSS (MB)")
    for s in samples:
        print(f"{s['episodes']:8d} {s['fds']:5d} {s['processes']:21d} {s['pipes']:10d} {s['rss_mb']:9.1f}")


def _assert_flat(samples: list[dict], envs: int, max_processes: int, max_pipes: int) -> None:
    """Flat once every env has made its pipes (each makes them at its first episode, and a second pair where it
    prepares its next episode at its first step)."""
    warm = next(s for s in samples if s["episodes"] >= envs)
    for s in samples[1:]:
        assert s["processes"] <= max_processes and s["pipes"] <= max_pipes, samples
        if s["episodes"] >= warm["episodes"]:
            assert s["fds"] <= warm["fds"] + 2 and s["pipes"] == warm["pipes"], samples
    assert samples[-1]["rss_mb"] - warm["rss_mb"] < 40, samples


@pytest.mark.slow
def test_soak_100_episodes_leave_descriptors_processes_pipes_and_memory_flat(tmp_path, no_leaks):
    t0 = time.monotonic()
    run = subprocess.run([sys.executable, "-m", "tests.faults.soak_workload", str(tmp_path)], cwd=SOURCE_ROOT,
                         capture_output=True, text=True, timeout=900)  # fmt: skip
    assert run.returncode == 0, run.stderr[-3000:]
    samples = json.loads(run.stdout.strip().splitlines()[-1])
    vector, single = samples["vector"], samples["single"]
    _report("2-worker vector env (-1: after close)", vector)
    # per worker: the template its episodes are forked from, a running and a prepared episode (engine/episodes/fork.py)
    _assert_flat(vector[:-1], envs=2, max_processes=6, max_pipes=4)
    _report(f"{SINGLE_ENVS} single envs in one process (-1: after close)", single)
    prepared = len(range(0, SINGLE_ENVS, PREPARED_EVERY))  # these prepare their next episode; the rest start cold
    processes = SINGLE_ENVS + 2 * prepared  # and fork their episodes from a template of their own
    _assert_flat(single[:-1], envs=SINGLE_ENVS, max_processes=processes, max_pipes=SINGLE_ENVS + prepared)
    start, end = vector[0], single[-1]
    assert end["fds"] <= start["fds"] + 2 and end["processes"] == 0 and end["pipes"] == 0
    print(f"\n100 episodes in {time.monotonic() - t0:.0f} s; fds {start['fds']} -> {end['fds']}, "
          f"RSS {start['rss_mb']:.0f} -> {end['rss_mb']:.0f} MB")  # fmt: skip
