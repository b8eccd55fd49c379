"""The exceptions users catch."""

from __future__ import annotations

from pathlib import Path


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


class ProtocolError(EnergyPlusError):
    """A malformed or truncated frame on the pipe."""
