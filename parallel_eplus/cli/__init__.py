"""`parallel-eplus`: the command line. `parser.py` declares it, `commands.py` runs each subcommand
(`evaluate.py` the evaluation, `deploy.py` export and serve, `many_runs.py` seeds, sweeps and the run registry).

The top layer: it may import every other folder; nothing imports it.
"""

from __future__ import annotations

import logging

from parallel_eplus.cli import extras
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
    needs = getattr(args, "needs", "train")  # every command but `serve`, `export` and `clean` runs the training stack
    if (absent := extras.missing(needs)) is not None:
        log.error("%s", extras.install_hint(absent, needs))
        return 2
    from parallel_eplus.errors import EnergyPlusError, Interrupts
    from parallel_eplus.io import DiskFullError

    try:
        with Interrupts():  # every command cleans up on Ctrl-C or SIGTERM, started in the background or not
            return args.func(args)
    except (EnergyPlusError, ValueError, FileNotFoundError, DiskFullError) as e:
        log.error("%s", e.strerror if isinstance(e, DiskFullError) else e)
        return 2
    except ModuleNotFoundError as e:
        if (extra := extras.extra_for(e.name or "")) is None:
            raise
        log.error("%s", extras.install_hint(e.name, extra))
        return 2
    except KeyboardInterrupt:
        log.warning("interrupted")
        return 130
