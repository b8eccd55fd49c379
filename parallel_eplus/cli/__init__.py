"""`parallel-eplus`: the command line. `parser.py` declares it, `commands.py` runs each subcommand
(`many_runs.py`: seeds, sweeps and the run registry).

The top layer: it may import every other folder; nothing imports it.
"""

from __future__ import annotations

import logging
import re
from importlib import metadata

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
    except ModuleNotFoundError as e:
        extra = _extra_for(e.name or "")
        if extra is None:
            raise
        log.error("%s is not installed: pip install 'parallel-eplus[%s]' (setup.sh installs all)", e.name, extra)
        return 2
    except KeyboardInterrupt:
        log.warning("interrupted")
        return 130


def _extra_for(module: str) -> str | None:
    """The extra (pyproject.toml) whose distribution provides `module`, so a command run in a lighter install (a
    controller server's `[serve]`) says what to install instead of a traceback; None if no extra has it."""
    top = module.split(".")[0]
    try:
        requirements = metadata.requires("parallel-eplus") or []
    except metadata.PackageNotFoundError:
        return None
    for requirement in requirements:  # e.g. 'torch==2.13.0; extra == "train"'
        found = re.match(r"\s*([A-Za-z0-9_.-]+).*;.*extra\s*==\s*[\"'](\w+)[\"']", requirement)
        if found and found[1].lower().replace("-", "_").removesuffix("_lbnl") == top:  # pyenergyplus-lbnl
            return found[2]
    return None
