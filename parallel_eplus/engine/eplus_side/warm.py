"""The EnergyPlus side of a long-lived process (engine/episodes/warm.py is ours): episode after episode, each in a
new API state, one JSON request a line on stdin, `done CODE` back on stdout when the episode is over.
"""

from __future__ import annotations

import contextlib
import json
import os
import signal
import sys
import traceback
from collections.abc import Callable


def serve(main: Callable[[list[str]], int]) -> int:
    """Run each request's episode (`main(argv)`: eplus_callback's) in turn in this process; answer `done CODE`."""
    from pyenergyplus.api import EnergyPlusAPI  # noqa: F401 - imported once, before the first request

    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C is the learner's to handle; it closes us
    reply = os.dup(1)  # our answers; fds 1 and 2 go to each episode's log
    null = os.open(os.devnull, os.O_WRONLY)
    os.dup2(null, 1)
    for line in sys.stdin.buffer:
        request = json.loads(line)
        code = 1
        try:
            log = os.open(request["log"], os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)
            os.dup2(log, 1)
            os.dup2(log, 2)
            os.close(log)
            code = main(request["argv"])
        except BaseException:  # noqa: BLE001 - an episode's failure is its own; the process serves the next
            traceback.print_exc()
        finally:
            with contextlib.suppress(Exception):
                sys.stdout.flush()
                sys.stderr.flush()
            os.dup2(null, 1)  # the log is closed: its folder may be pruned or removed
            os.dup2(null, 2)
        os.write(reply, f"done {code}\n".encode())
    return 0
