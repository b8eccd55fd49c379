"""TRPO, PPO and SAC on one budget (CA-CO-FL, six observations, the paper's reward): figure and table.

Resumable: rerun the same command after an interruption and finished chunks are skipped.
Full run (hours per algorithm on 2 cores):
    PYTHONPATH=. .venv/bin/python studies/algorithms/compare_algorithms.py --out results/compare
Smoke run:
    PYTHONPATH=. .venv/bin/python studies/algorithms/compare_algorithms.py --out /tmp/compare --timesteps 4096 \
        --eval-every 2048 --batch-size 2048 --run-days 7 --eval-days 7
"""

from __future__ import annotations

import argparse
import logging
from pathlib import Path

from parallel_eplus.experiments.compare import compare_figure, compare_table, references, run_comparison
from parallel_eplus.training.config import TrainConfig


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--out", type=Path, default=Path("results/compare"))
    p.add_argument("--algorithms", default="trpo,ppo,sac")
    p.add_argument("--timesteps", type=int, default=1_000_000)
    p.add_argument("--eval-every", type=int, default=200_000, help="env steps per chunk (evaluated after each)")
    p.add_argument("--batch-size", type=int, default=16384, help="TRPO/PPO steps per update (the paper's)")
    p.add_argument("--run-days", type=int, default=365, help="training episode length")
    p.add_argument("--eval-days", type=int, default=365, help="evaluation episode length")
    p.add_argument("--workers", type=int, default=2)
    p.add_argument("--seeds", default="0", help="comma-separated: each algorithm trains once per seed (default 0)")
    p.add_argument("--references", type=Path, default=Path("results/paper/results.csv"),
                   help="results.csv holding the Baseline and Rule-based rows")  # fmt: skip
    args = p.parse_args()
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(levelname)s %(message)s")
    base = TrainConfig(workers=args.workers, weathers=["CA", "CO", "FL"], run_days=args.run_days,
                       batch_size=args.batch_size, tensorboard_dir=str(args.out / "tensorboard"))  # fmt: skip
    seeds = [int(s) for s in args.seeds.split(",")]
    progress = run_comparison(args.out, args.algorithms.split(","), args.timesteps, args.eval_every, base,
                              args.eval_days, seeds)  # fmt: skip
    refs = references(args.references)
    figure = compare_figure(progress, refs, args.out / "compare.png")
    table = compare_table(progress, refs)
    (args.out / "compare.md").write_text(table)
    print(table)
    print(f"written: {figure}, {args.out / 'compare.md'}, {args.out / 'progress.csv'}")


if __name__ == "__main__":
    main()
