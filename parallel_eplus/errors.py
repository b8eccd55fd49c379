"""The exceptions users catch, and the signals that become one."""

from __future__ import annotations

import re
import signal
import threading
from pathlib import Path

_SEVERE = re.compile(r"\*\*\s+(Severe|Fatal)\s+\*\*")  # EnergyPlus's "** Severe  **", "**  Fatal  **"


class EnergyPlusError(RuntimeError):
    """EnergyPlus failed to start, rejected the model, died, hung or broke the protocol.

    Carries the episode directory and the tail of EnergyPlus's error file, so the message alone says
    what went wrong and where to look.
    """

    def __init__(self, message: str, episode_dir: Path | None = None, err_tail: str = ""):
        self.episode_dir = episode_dir
        self.err_tail = err_tail
        text = message
        if episode_dir is not None:
            text += f"\n  episode directory: {episode_dir}"
        if err_tail:
            text += "\n  tail of the EnergyPlus log:\n" + "\n".join("    " + ln for ln in err_tail.splitlines())
        super().__init__(text)

    @property
    def headline(self) -> str:
        """One line for a log or a table: the message's first line and EnergyPlus's own first severe error
        (the cause, usually; the tail of a long error file holds only its summary)."""
        first = (str(self).strip().splitlines() or [type(self).__name__])[0]
        err = Path(self.episode_dir) / "eplusout.err" if self.episode_dir else None
        lines = err.read_text(errors="replace").splitlines() if err and err.is_file() else self.err_tail.splitlines()
        severe = next((ln.strip() for ln in lines if _SEVERE.search(ln)), None)
        return f"{first}; {severe}" if severe else first


class ProtocolError(EnergyPlusError):
    """A malformed or truncated frame on the pipe."""


class Interrupts:
    """SIGINT and SIGTERM raise KeyboardInterrupt inside the block, so `finally` clauses stop
    EnergyPlus and remove the pipes.

    SIGINT too, explicitly: a process started in the background by a shell (`cmd &`, nohup, CI
    runners) inherits SIGINT as ignored, and `kill -INT` would then do nothing at all.

    Off the main thread (a Ray Tune trial runs its training in one) signals cannot be caught: there the
    block changes nothing, and whoever runs the thread stops it (experiments/tune_trial.py).
    """

    SIGNALS = (signal.SIGINT, signal.SIGTERM)

    def __enter__(self):
        main = threading.current_thread() is threading.main_thread()
        self._old = {s: signal.signal(s, self._raise) for s in self.SIGNALS} if main else {}
        return self

    @staticmethod
    def _raise(signum, frame):
        raise KeyboardInterrupt(f"signal {signum}")

    def __exit__(self, *exc):
        for s, handler in self._old.items():
            signal.signal(s, handler)
        return False


class RunExistsError(ValueError):
    """A new training run was given the name of an existing one (runs/run_names.py)."""


class WorkerLostError(EnergyPlusError):
    """A Ray actor (and the EnergyPlus workers in it) was lost or stopped answering: its node died,
    was cut off, or the actor hung. Training saves a checkpoint and stops (`train --resume` goes on)."""
