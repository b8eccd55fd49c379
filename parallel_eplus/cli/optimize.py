"""`parallel-eplus optimize MODEL.idf|SPEC.toml [...] --out DIR`: a building in, a saving and a controller out
(parallel_eplus/optimize/). `add_optimize` declares the subcommand (parser.py calls it); `main` runs it alone, for a
tree whose parser does not list it yet."""

from __future__ import annotations

import argparse
import os
from pathlib import Path

EPILOG = """\
Stages (each kept in DIR, its log in DIR/logs/): prepare (building init with the starter's recommended actions and the
example tariff, building check; a spec is used as given), BOPTEST's test periods found once per weather, the own
controls scored, Guideline 36's supply-air reset scored where the spec has supply-air actions (a refusal is reported),
the building's preset trained (thermostat-planner, on the reset where it applies; datacenter-planner for data centers)
and scored with the preset's evaluation settings, the choice on the held-out weathers only (the own controls unless a
candidate is at least 0.5 % lower at no more occupied discomfort), the export into DIR/controller/, DIR/report.md.
Ctrl-C, or a rerun of the same command, continues where it stopped; a rerun with a larger --budget-minutes trains on."""


def _names(text: str) -> tuple[str, ...]:
    return tuple(w.strip() for w in text.split(",") if w.strip())


def add_optimize(sub) -> argparse.ArgumentParser:
    """The `optimize` subcommand with its options."""
    op = sub.add_parser(
        "optimize", help="a building in, a saving and a controller out: score its own controls, a rule and a "
        "learned controller on held-out weathers, choose, export, report", epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )  # fmt: skip
    op.add_argument("sources", nargs="+", metavar="MODEL.idf|SPEC.toml|FOLDER",
                    help="one building (optimized in DIR) or several, or folders of them (each in DIR/<name>/, and "
                    "DIR/summary.md); a built-in spec's name works too")  # fmt: skip
    op.add_argument("--out", type=Path, default=Path("optimized"), help="the folder DIR (default optimized)")
    op.add_argument("--weathers", type=_names, default=("CA", "CO", "FL"),
                    help="training weathers: trained and chosen on (default CA,CO,FL)")  # fmt: skip
    op.add_argument(
        "--held-out",
        type=_names,
        default=("IL", "VA"),
        help="held-out weathers: never trained on, used for the final choice only (default IL,VA)",
    )
    op.add_argument(
        "--objective",
        choices=("hvac", "cost"),
        default="hvac",
        help="what to lower: HVAC energy (default) or the electricity bill (cost; training too)",
    )
    op.add_argument(
        "--budget-minutes",
        type=float,
        default=45.0,
        help="per building, over every session (default 45): training gets what is left after scoring",
    )
    op.add_argument("--workers", type=int, default=os.cpu_count() or 1, help="EnergyPlus processes (default: cores)")
    op.add_argument("--preset", help="the learned controller's preset (default: the building's; `parallel-eplus "
                    "presets` lists them)")  # fmt: skip
    op.add_argument("--timesteps", type=int, help="training steps (default: the preset's)")
    op.add_argument("--run-days", type=int, help="training episode length, days (default: the preset's)")
    op.add_argument("--scenarios", type=_names, default=("peak_heat", "typical_heat", "peak_cool", "typical_cool"),
                    help="BOPTEST's test periods scored (default all four)")  # fmt: skip
    op.add_argument(
        "--scenario-days",
        type=int,
        default=14,
        help="scored days of each test period around its day (default 14, BOPTEST's; warm-up min(7, N))",
    )
    op.add_argument("--quick", action="store_true",
                    help="a smoke run of every stage, not a result: one fixed window (January 11-12 after a day's "
                    "warm-up) instead of BOPTEST's periods (no year runs), 2-day training episodes, 600 training "
                    "steps of a smaller planner search; the report says so")  # fmt: skip
    op.add_argument("--ray", metavar="ADDRESS",
                    help="run the buildings at once as Ray tasks, --workers cores each, on the cluster at ADDRESS "
                    "(`local`: a Ray of this machine's cores); --out must be a folder every node sees at the same "
                    "path")  # fmt: skip
    op.add_argument("--quiet", action="store_true", help="no progress bars")
    op.set_defaults(func=cmd_optimize)
    return op


def cmd_optimize(args: argparse.Namespace) -> int:
    from parallel_eplus.optimize import OptimizeSettings, run_optimize

    settings = OptimizeSettings(
        weathers=args.weathers, held_out=args.held_out, scenarios=args.scenarios, scenario_days=args.scenario_days,
        quick=args.quick, objective=args.objective, preset=args.preset, timesteps=args.timesteps,
        run_days=args.run_days, workers=args.workers, budget_minutes=args.budget_minutes,
    )  # fmt: skip
    if settings.preset:
        from parallel_eplus.presets.catalog import load_preset

        load_preset(settings.preset)  # an unknown name fails here, listing the presets
    return run_optimize(args.sources, args.out, settings, show=not args.quiet, ray_address=args.ray)


def main(argv: list[str] | None = None) -> int:
    """`parallel-eplus optimize ARGS` with a parser of its own (the errors, logging and interrupts of cli.main)."""
    import logging
    import sys

    from parallel_eplus.errors import EnergyPlusError, Interrupts

    parser = argparse.ArgumentParser(prog="parallel-eplus")
    parser.add_argument("-v", "--verbose", action="store_true", help="debug logging")
    add_optimize(parser.add_subparsers(dest="command", required=True))
    args = parser.parse_args(["optimize", *(sys.argv[1:] if argv is None else argv)])
    logging.basicConfig(level=logging.DEBUG if args.verbose else logging.INFO,
                        format="%(asctime)s %(levelname)s %(name)s: %(message)s")  # fmt: skip
    log = logging.getLogger("parallel_eplus")
    try:
        with Interrupts():
            return args.func(args)
    except (EnergyPlusError, ValueError, FileNotFoundError) as e:
        log.error("%s", e)
        return 2
    except KeyboardInterrupt:
        log.warning("interrupted: rerun the same command to continue")
        return 130


if __name__ == "__main__":
    raise SystemExit(main())
