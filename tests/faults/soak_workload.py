"""The soak's workload (test_soak.py), run in an interpreter of its own: its descriptors are then only what this
package opens, not what earlier tests' libraries (Ray's gRPC threads) open and close meanwhile in pytest's process.

    python -m tests.faults.soak_workload OUT_DIR   # prints {"vector": [samples], "single": [samples]} as JSON
"""

from __future__ import annotations

import json
import os
import sys
import tempfile
from pathlib import Path

import numpy as np

from parallel_eplus import EnergyPlusEnv
from parallel_eplus.engine.config import SimulationConfig
from parallel_eplus.envs.vector_env import EnergyPlusVectorEnv

VECTOR_EPISODES, SINGLE_EPISODES, SINGLE_ENVS = 50, 50, 16
PREPARED_EVERY = 4  # every 4th single env prepares its next episode (each costs a second EnergyPlus process)


def _energyplus_children() -> int:
    """EnergyPlus-side processes this process started that are alive, with the episodes forked from its templates
    (engine/episodes/fork.py: their parent is the template)."""
    parents = {}
    for proc in Path("/proc").iterdir():
        try:
            if proc.name.isdigit() and b"parallel_eplus.engine.eplus_side.callback" in (proc / "cmdline").read_bytes():
                parents[proc.name] = (proc / "stat").read_text().rsplit(")", 1)[1].split()[1]
        except (OSError, IndexError):  # gone meanwhile
            continue
    ours = {pid for pid, parent in parents.items() if parent == str(os.getpid())}
    return len(ours) + sum(parent in ours for parent in parents.values())


def sample(episodes: int) -> dict:
    status = Path("/proc/self/status").read_text()
    rss_kb = int(next(ln for ln in status.splitlines() if ln.startswith("VmRSS:")).split()[1])
    pipes = [d for d in os.listdir(tempfile.gettempdir()) if d.startswith(f"parallel-eplus-{os.getpid()}-")]
    return {
        "episodes": episodes, "fds": len(os.listdir("/proc/self/fd")), "processes": _energyplus_children(),
        "pipes": len(pipes), "rss_mb": rss_kb / 1024,
    }  # fmt: skip


def vector(out: Path) -> list[dict]:
    """50 one-day episodes through one 2-worker vector env; the last sample is after closing it (episodes -1)."""
    samples = [sample(0)]
    venv = EnergyPlusVectorEnv(SimulationConfig(run_days=1, output_dir=str(out / "v"), keep_episodes=1),
                               [["CA"], ["FL"]])  # fmt: skip
    try:
        venv.reset(seed=0)
        done = 0
        while done < VECTOR_EPISODES:
            _, _, terminated, truncated, _ = venv.step(np.zeros((2, 4), dtype=np.float32))
            if truncated.any():
                raise RuntimeError("an episode was cut short")
            if terminated.any():
                done += int(terminated.sum())
                if done % 10 == 0 or done == 2:
                    samples.append(sample(done))
    finally:
        venv.close()
    return [*samples, {**sample(done), "episodes": -1}]


def single(out: Path) -> list[dict]:
    """50 one-day episodes through 16 single envs open at once (every 4th prepares its next episode, and the
    seeded resets discard what it prepared); the last sample is after closing them."""
    envs = [EnergyPlusEnv(weather="CO", run_days=1, output_dir=out / f"s{i}", keep_episodes=1,
                          prepare_next=i % PREPARED_EVERY == 0)
            for i in range(SINGLE_ENVS)]  # fmt: skip
    samples = [sample(0)]
    try:
        for k in range(SINGLE_EPISODES):
            env = envs[k % SINGLE_ENVS]
            env.reset(seed=k)
            terminated = False
            while not terminated:
                _, _, terminated, truncated, _ = env.step(np.zeros(4, dtype=np.float32))
                if truncated:
                    raise RuntimeError("an episode was cut short")
            if (k + 1) % 10 == 0 or k == 1:
                samples.append(sample(k + 1))
    finally:
        for env in envs:
            env.close()
    return [*samples, {**sample(SINGLE_EPISODES), "episodes": -1}]


if __name__ == "__main__":
    out = Path(sys.argv[1])
    print(json.dumps({"vector": vector(out), "single": single(out)}))
