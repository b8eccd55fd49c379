"""`parallel-eplus boptest`: BOPTEST's service API over every shipped building and the specs of a folder
(deploy/boptest/, docs/boptest.md). `add_boptest` declares the subcommand (parser.py calls it)."""

from __future__ import annotations

import argparse
from pathlib import Path


def add_boptest(sub) -> argparse.ArgumentParser:
    bt = sub.add_parser(
        "boptest", help="serve BOPTEST's REST API (select, initialize, advance, kpi, ...) over every building: "
        "BOPTEST's clients (BOPTEST-Gym) run unmodified, each test an EnergyPlus episode",
    )  # fmt: skip
    bt.add_argument("--specs", type=Path, metavar="DIR", help="a folder of building specs (.toml) served as test "
                    "cases beside the shipped buildings (a spec's file name is its test case's name)")  # fmt: skip
    bt.add_argument("--host", default="127.0.0.1", help="address to listen on (default 127.0.0.1; 0.0.0.0: all)")
    bt.add_argument("--port", type=int, default=8000, help="TCP port to listen on (default 8000)")
    bt.add_argument("--token-file", type=Path, metavar="FILE",
                    help="a secret on its first line: every request must send Authorization: Bearer <it> "
                    "(required off loopback)")  # fmt: skip
    bt.add_argument(
        "--workers",
        type=int,
        default=2,
        help="tests running at once, each its EnergyPlus process (default 2); more wait Queued",
    )
    bt.add_argument("--idle-timeout", type=float, default=900.0, metavar="S",
                    help="a test without a request for S seconds is stopped, its process and files removed "
                    "(default 900)")  # fmt: skip
    bt.add_argument("--ray", metavar="ADDRESS", help="run each test in a Ray actor on the cluster at ADDRESS "
                    "(`local`: a Ray of our own); docs/cluster.md for its token")  # fmt: skip
    bt.add_argument("--cache", type=Path, metavar="DIR", help="where BOPTEST's test periods found per building and "
                    "weather are kept (default ~/.cache/parallel-eplus/boptest)")  # fmt: skip
    bt.set_defaults(func=cmd_boptest)
    return bt


def cmd_boptest(args: argparse.Namespace) -> int:
    try:
        from parallel_eplus.deploy.boptest.app import serve
    except ImportError as e:
        raise ValueError(f"{e.name} is not installed: pip install 'parallel-eplus[serve]' (scripts/setup.sh does)") \
            from None  # fmt: skip
    from parallel_eplus.deploy.boptest.registry import testcases_of

    serve(testcases_of(args.specs), args.host, args.port, args.token_file, args.workers, args.idle_timeout,
          args.ray, args.cache)  # fmt: skip
    return 0
