"""RLlib's PPO on the data center: two env runners, each stepping its own EnergyPlus process.

Every runner gets the same `env_config`, so both write episodes to one `output_dir`; each episode still gets a
folder of its own (`episode-NNNNNN-<weather>`, engine/episode.py). docs/rllib.md shows a run.

    .venv/bin/python scripts/rllib_ppo.py --iterations 3 --output-dir episodes
"""

from __future__ import annotations

import argparse
from pathlib import Path

from ray.rllib.algorithms.ppo import PPOConfig

ENV = "parallel_eplus:parallel_eplus/DataCenter-v0"  # "module:id": each runner imports the package, registering it


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--iterations", type=int, default=3)
    parser.add_argument("--run-days", type=int, default=1, help="episode length (one day: 96 steps)")
    parser.add_argument("--output-dir", type=Path, default=Path("episodes"))
    args = parser.parse_args()

    config = (
        PPOConfig()
        .environment(ENV, env_config={
            "weather": ["CA", "FL"],  # cycled episode by episode
            "run_days": args.run_days,
            "output_dir": str(args.output_dir.resolve()),  # absolute: Ray workers need not share our directory
            "keep_episodes": 2,  # each env keeps its newest 2 episodes whole, older ones their summary.json
        })
        .env_runners(num_env_runners=2, num_cpus_per_env_runner=1)
        # Untrained exploration can heat a zone until EnergyPlus stops with a fatal error (EnergyPlusError): start
        # that env afresh, as our own trainer restarts the episode, instead of losing the env runner.
        .fault_tolerance(restart_failed_sub_environments=True)
        .training(train_batch_size_per_learner=2 * 96 * args.run_days, minibatch_size=64, num_epochs=4, lr=3e-4)
    )  # fmt: skip
    algo = config.build_algo()
    try:
        for i in range(1, args.iterations + 1):
            result = algo.train()
            runners = result["env_runners"]
            print(f"iteration {i}: {int(result['num_env_steps_sampled_lifetime'])} env steps, "
                  f"{int(runners.get('num_episodes_lifetime', 0))} episodes, "
                  f"mean return {runners.get('episode_return_mean', float('nan')):.2f}")  # fmt: skip
    finally:
        algo.stop()  # closes every env: no EnergyPlus process or pipe left
    for folder in sorted(args.output_dir.iterdir()):
        print(folder)


if __name__ == "__main__":
    main()
