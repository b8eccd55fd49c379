"""`parallel-eplus`: the command line. `parser.py` declares it, `commands.py` runs each subcommand
(`many_runs.py`: seeds, sweeps and the run registry).

The top layer: it may import every other folder; nothing imports it.
"""

from __future__ import annotations

import logging

from parallel_eplus.cli.parser import build_parser

log = logging.getLogger("parallel_eplus")

__all__ = ["build_parser", "main"]


def main(argv: list[str] | None = None) -> int:
    """Run `parallel-eplus ARGS`; returns the exit code (2: a clear one-line error, 130: interrupted)."""
    parser = build_parser()
    args = parser.parse_args(argv)
    logging.basicConfig(
        level=logging.DEBUG if args.verbose else logging.INFO,
        format="%(asctime)s %(levelname)s %(name)s: %(message)s",
    )
    from parallel_eplus.errors import EnergyPlusError, Interrupts
    from parallel_eplus.io import DiskFullError

    try:
        with Interrupts():  # every command cleans up on Ctrl-C or SIGTERM, started in the background or not
            return args.func(args)
    except (EnergyPlusError, ValueError, FileNotFoundError, DiskFullError) as e:
        log.error("%s", e.strerror if isinstance(e, DiskFullError) else e)
        return 2
    except KeyboardInterrupt:
        log.warning("interrupted")
        return 130
