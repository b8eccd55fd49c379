"""RLlib is a client like any other: its PPO trains on the env with two env runners sharing one output folder."""

from __future__ import annotations

import json

import pytest

from parallel_eplus.buildings.datacenter import STEPS_PER_DAY
from parallel_eplus.engine.episode import SUMMARY_FILE


def _runner_state(runner) -> dict:
    """What one env runner's env has done: episodes begun and the folder of the current one."""
    import os

    sim = runner.env.unwrapped.envs[0].unwrapped.sim
    return {"pid": os.getpid(), "episodes": sim.episode, "current": str(sim.episode_dir)}


@pytest.mark.slow
def test_rllib_ppo_trains_with_two_env_runners_sharing_one_output_dir(tmp_path, no_leaks):
    ray = pytest.importorskip("ray")
    from ray.rllib.algorithms.ppo import PPOConfig
    from ray.tune.registry import register_env

    from parallel_eplus.envs.env import rllib_env

    out = tmp_path / "episodes"
    ray.init(address="local", num_cpus=2, include_dashboard=False)
    try:
        register_env("parallel_eplus-datacenter", rllib_env)  # as scripts/rllib_ppo.py: episodes name their runner
        config = (
            PPOConfig()
            .environment(
                "parallel_eplus-datacenter",
                env_config={"weather": "CA", "run_days": 1, "output_dir": str(out), "keep_episodes": 1},
            )
            .env_runners(num_env_runners=2, num_cpus_per_env_runner=1)
            .fault_tolerance(restart_failed_env_runners=False)  # a runner that fails fails the test
            # Seeded: untrained exploration can heat a zone past EnergyPlus's limits (once, in CI: the west zone at
            # 144 C, its surfaces past 200 C, a fatal error); a fixed seed makes the test's actions the same each run.
            .debugging(seed=0)
            .training(train_batch_size_per_learner=2 * STEPS_PER_DAY, minibatch_size=64, num_epochs=1)
        )
        algo = config.build_algo()
        try:
            try:
                results = [algo.train() for _ in range(2)]  # 2: each runner's first episode is pruned
            except Exception as e:  # an env runner's error: its own cause, short, where CI's log cut shows it
                cause = str(e).strip().splitlines()
                short = "\n".join(cause[:3] + ["..."] + cause[-25:])
                pytest.fail(f"RLlib training failed: {type(e).__name__}: {short}")
            runners = algo.env_runner_group.foreach_env_runner(_runner_state, local_env_runner=False)
            restarts = algo.env_runner_group.num_remote_worker_restarts()
        finally:
            algo.stop()
    finally:
        ray.shutdown()
    assert results[-1]["num_env_steps_sampled_lifetime"] == 2 * 2 * STEPS_PER_DAY and restarts == 0
    assert len({r["pid"] for r in runners}) == 2 and all(r["episodes"] >= 2 for r in runners), runners
    folders = sorted(out.iterdir())
    # Both runners began CA episode 1, 2 (and maybe 3) on the same config: every one has a folder of its own.
    assert len(folders) == sum(r["episodes"] for r in runners), (folders, runners)
    assert all(f.name.startswith("episode-") and f.name.endswith("-CA") for f in folders)
    workers = [json.loads((f / SUMMARY_FILE).read_text())["worker"] for f in folders if (f / SUMMARY_FILE).is_file()]
    assert set(workers) == {"runner-1", "runner-2"}, workers  # each summary names the env runner that ran it
    finished = [json.loads((f / SUMMARY_FILE).read_text()) for f in folders if (f / SUMMARY_FILE).is_file()]
    assert len([s for s in finished if s["complete"] and s["steps"] == STEPS_PER_DAY]) >= 4
    # keep_episodes=1: each env keeps its own newest whole and prunes only its own older ones
    whole = [str(f) for f in folders if (f / "steps.parquet").is_file()]
    assert sorted(whole) == sorted(r["current"] for r in runners)
