"""Envs, vector envs and whole runs given one output folder each get their own episode directories."""

from __future__ import annotations

import json
import subprocess
import sys
from concurrent.futures import ThreadPoolExecutor

import numpy as np
import pytest

from parallel_eplus import EnergyPlusEnv
from parallel_eplus.buildings.datacenter import STEPS_PER_DAY
from parallel_eplus.engine.episode import SUMMARY_FILE, claim_episode_dir


def test_a_claimed_name_is_never_handed_out_twice_nor_replaced(tmp_path):
    old = tmp_path / "episode-000001-CA"
    old.mkdir()
    (old / "steps.parquet").write_text("an earlier run's")
    path, n = claim_episode_dir(tmp_path, "CA", 1)  # what a second env with its own counter would ask for
    assert (path.name, n) == ("episode-000002-CA", 2)
    assert (old / "steps.parquet").read_text() == "an earlier run's"
    assert claim_episode_dir(tmp_path, "FL")[0].name == "episode-000003-FL"  # above the folder's highest
    with ThreadPoolExecutor(8) as pool:  # eight claimants, each counting from 1 on its own
        claimed = list(pool.map(lambda _: claim_episode_dir(tmp_path, "CO", 1)[0], range(32)))
    assert len(set(claimed)) == 32 and all(p.is_dir() for p in claimed)


def _run(env: EnergyPlusEnv, episodes: int) -> list[str]:
    dirs = []
    for _ in range(episodes):
        env.reset()
        terminated = False
        while not terminated:
            _, _, terminated, _, info = env.step(np.zeros(4, dtype=np.float32))
        dirs.append(info["episode_dir"])
    return dirs


@pytest.mark.slow
def test_two_envs_in_one_process_sharing_a_folder_keep_every_episode(tmp_path, no_leaks):
    """Stepped side by side (both EnergyPlus processes alive at once), two episodes each, keeping one whole."""
    envs = [EnergyPlusEnv(weather=w, run_days=1, output_dir=tmp_path, keep_episodes=1) for w in ("CA", "FL")]
    try:
        dirs: list[list[str]] = [[], []]
        for _ in range(2):
            for env in envs:
                env.reset()
            for _ in range(STEPS_PER_DAY - 1):
                for env in envs:
                    env.step(np.zeros(4, dtype=np.float32))
            for i, env in enumerate(envs):
                *_, terminated, _, info = env.step(np.zeros(4, dtype=np.float32))
                assert terminated
                dirs[i].append(info["episode_dir"])
    finally:
        for env in envs:
            env.close()
    names = sorted(p.name for p in tmp_path.iterdir())
    assert names == [
        "episode-000001-CA", "episode-000002-FL", "episode-000003-CA", "episode-000004-FL"
    ]  # fmt: skip
    for own in dirs:
        summaries = [json.loads((tmp_path / d / SUMMARY_FILE).read_text()) for d in own]
        assert [s["steps"] for s in summaries] == [STEPS_PER_DAY] * 2 and [s["episode"] for s in summaries] == [1, 2]
        assert not (tmp_path / own[0] / "steps.parquet").exists()  # keep_episodes=1 prunes the env's own older one
        assert (tmp_path / own[1] / "steps.parquet").is_file()  # and never the other env's newest


@pytest.mark.slow
def test_two_processes_given_the_same_output_dir_both_finish_with_their_own_folders(tmp_path, no_leaks):
    out = tmp_path / "episodes"
    cmd = [sys.executable, "-m", "parallel_eplus.cli", "simulate", "--days", "1", "--quiet", "--output-dir", str(out)]
    procs = [subprocess.Popen([*cmd, "--weather", w], stdout=subprocess.PIPE, text=True) for w in ("CA", "FL")]
    outputs = [p.communicate(timeout=600)[0] for p in procs]
    assert [p.returncode for p in procs] == [0, 0], outputs
    printed = sorted(ln.split(": ", 1)[1] for o in outputs for ln in o.splitlines() if ln.startswith("episode records"))
    assert len(set(printed)) == 2 and sorted(str(p) for p in out.iterdir()) == printed
    for d in printed:
        summary = json.loads((out.joinpath(d) / SUMMARY_FILE).read_text())
        assert summary["steps"] == STEPS_PER_DAY and summary["complete"]
    assert {json.loads((out / d / SUMMARY_FILE).read_text())["weather"] for d in printed} == {"CA", "FL"}
