"""Simulations still open when the interpreter exits, closed while the modules they need are alive.

An uncaught Ctrl-C in a script that never called close() left them to `__del__` at shutdown, where writing the
episode's records failed inside pandas ("'NoneType' object has no attribute 'filters'") and the step table was lost.
"""

from __future__ import annotations

import atexit
import logging
import weakref

_LIVE: weakref.WeakSet = weakref.WeakSet()


def close_at_exit(sim) -> None:
    """Have `sim.close()` called at interpreter exit if it is still alive then."""
    _LIVE.add(sim)


@atexit.register
def _close_live() -> None:
    for sim in list(_LIVE):
        try:
            sim.close()
        except Exception:  # noqa: BLE001 - one failing close must not keep the others' processes alive
            logging.getLogger(__name__).exception("closing %s at exit", getattr(sim, "name", "a simulation"))
