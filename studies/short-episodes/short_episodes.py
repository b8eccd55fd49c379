"""Short episodes against EnergyPlus alone (issue 39): rerun on a quiet machine for the figures in docs/speed.md.

    python studies/short-episodes/short_episodes.py --days 1 7 --episodes 10 --pairs 3   # consecutive episodes, resets
    python studies/short-episodes/short_episodes.py --train --days 1 7 14 365 --pairs 1  # TRPO steps/s by length
    python studies/short-episodes/short_episodes.py --train --long-lived --days 1 7 365  # forked against long-lived

What each measures: parallel_eplus/bench/short.py.
"""

from __future__ import annotations

import argparse
import json
import logging
import sys
import tempfile
from pathlib import Path

from parallel_eplus.bench.short import consecutive, parked_resets, training


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--days", type=int, nargs="+", default=[1, 7])
    p.add_argument("--episodes", type=int, default=10)
    p.add_argument("--pairs", type=int, default=3)
    p.add_argument("--weather", default="CA")
    p.add_argument("--resets", type=int, default=30, help="resets timed with the prepared episode parked")
    p.add_argument("--train", action="store_true", help="TRPO steps/s by episode length instead")
    p.add_argument("--train-steps", type=int, default=16384)
    p.add_argument("--cold", action="store_true", help="each also with cold starts (prepare_next off), paired")
    p.add_argument(
        "--long-lived",
        action="store_true",
        help="each also prepared in long-lived processes instead of forked (fork_episodes off), paired",
    )
    p.add_argument("--out", type=Path, help="write the figures as JSON here")
    args = p.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(message)s")
    if args.train:
        out = training(args.days, args.train_steps, args.pairs, args.cold, args.long_lived)
    else:
        modes = ("prepared", *(["long_lived"] if args.long_lived else []), *(["cold"] if args.cold else []))
        out = {f"{d}d": consecutive(d, args.episodes, args.pairs, args.weather, modes) for d in args.days}
        with tempfile.TemporaryDirectory(prefix="parallel-eplus-short-") as tmp:
            out["parked"] = parked_resets(1, args.resets, args.weather, Path(tmp))
    text = json.dumps(out, indent=2)
    print(text)
    if args.out:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text(text + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
