"""`parallel-eplus building ...` subcommands kept out of cli.py: `check` (buildings/check.py)."""

from __future__ import annotations

import argparse


def cmd_check(args: argparse.Namespace) -> int:
    from parallel_eplus.buildings.check import check_building

    spec = check_building(args.spec, args.weather, use_cache=False)
    n_act = sum(len(a.actuators) for a in spec.actions)
    print(f"{spec.path}: ok: {len(spec.observations)} observations and {n_act} actuators resolve in {spec.idf.name}")
    return 0


def add_check(sub) -> None:
    ck = sub.add_parser("check", help="resolve every observation and actuator of a spec against its model")
    ck.add_argument("spec", help="a building spec (TOML)")
    ck.add_argument("--weather", help="weather for the short run (default: the spec's first, else CA)")
    ck.set_defaults(func=cmd_check)
