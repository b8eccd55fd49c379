"""RLlib's PPO on the data center: two env runners, each stepping its own EnergyPlus process.

Every runner gets the same `env_config`, so both write episodes to one folder; each episode still gets a folder of
its own (`episode-NNNNNN-<weather>`, engine/episode.py), and its summary names the runner (`worker`:
`runner-1`, `runner-2`; envs/env.py `rllib_env`). Everything goes under `--output-dir`: `episodes/`, and
`checkpoint/`, the trained algorithm (`Algorithm.from_checkpoint` restores it), and `rllib/`, RLlib's own log folder
(by default ~/ray_results). docs/rllib.md shows a run.

    .venv/bin/python scripts/rllib_ppo.py --iterations 3 --output-dir runs/rllib
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import ray.tune.trainable.trainable as trainable
from ray.rllib.algorithms.ppo import PPOConfig
from ray.tune.registry import register_env

from parallel_eplus.envs.env import rllib_env


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--iterations", type=int, default=3)
    parser.add_argument("--run-days", type=int, default=1, help="episode length (one day: 96 steps)")
    parser.add_argument("--output-dir", type=Path, default=Path("runs") / "rllib")
    args = parser.parse_args()
    out = args.output_dir.resolve()  # absolute: Ray workers need not share our directory
    episodes = out / "episodes"

    register_env("parallel_eplus-datacenter", rllib_env)  # each runner's env names its runner in its episodes
    config = (
        PPOConfig()
        .environment("parallel_eplus-datacenter", env_config={
            "weather": ["CA", "FL"],  # cycled episode by episode
            "run_days": args.run_days,
            "output_dir": str(episodes),
            "keep_episodes": 2,  # each env keeps its newest 2 episodes whole, older ones their summary.json
        })
        .env_runners(num_env_runners=2, num_cpus_per_env_runner=1)
        # Untrained exploration can heat a zone until EnergyPlus stops with a fatal error (EnergyPlusError): start
        # that env afresh, as our own trainer restarts the episode, instead of losing the env runner.
        .fault_tolerance(restart_failed_sub_environments=True)
        .training(train_batch_size_per_learner=2 * 96 * args.run_days, minibatch_size=64, num_epochs=4, lr=3e-4)
    )  # fmt: skip
    # An Algorithm outside Ray Tune makes itself a log folder under ~/ray_results (Ray's DEFAULT_STORAGE_PATH, read
    # when it starts; no setting moves it): here it goes under --output-dir instead.
    trainable.DEFAULT_STORAGE_PATH = str(out / "rllib")
    algo = config.build_algo()
    try:
        for i in range(1, args.iterations + 1):
            result = algo.train()
            runners = result["env_runners"]
            print(f"iteration {i}: {int(result['num_env_steps_sampled_lifetime'])} env steps, "
                  f"{int(runners.get('num_episodes_lifetime', 0))} episodes, "
                  f"mean return {runners.get('episode_return_mean', float('nan')):.2f}")  # fmt: skip
        checkpoint = algo.save_to_path(str(out / "checkpoint"))
    finally:
        algo.stop()  # closes every env: no EnergyPlus process or pipe left
    for folder in sorted(episodes.iterdir()):
        summary = folder / "summary.json"
        worker = json.loads(summary.read_text()).get("worker", "?") if summary.is_file() else "?"
        print(f"{folder}  ({worker})")
    print(f"checkpoint: {checkpoint}")


if __name__ == "__main__":
    main()
