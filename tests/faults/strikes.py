"""Faults that strike at a moment the test controls, never after a delay.

A worker is struck right after it has reported a step: its EnergyPlus process has written the observation
and waits for the next action, so it cannot end its episode before the strike lands (a timed strike could
land while the episode was already finishing, which loses nothing, and the test then never saw a fault).
"""

from __future__ import annotations

import os
import signal
import time

from parallel_eplus.engine.simulation import Simulation


def strike_after_step(monkeypatch, sig: int, worker: str = "0", episode: int = 2, step: int = 10) -> list[int]:
    """Send `sig` to worker `worker`'s EnergyPlus once it has reported step `step` of its `episode`-th
    episode (counted from 1, restarts included), in this process's training run or vector env.

    Returns the list the struck PID is appended to. `step` must be below the episode's length.
    """
    hit: list[int] = []
    receive = Simulation.receive

    def striking_receive(self: Simulation):
        answer = receive(self)
        due = self.name == worker and self.episode == episode and self.records is not None and self.records.n == step
        if due and not hit:
            hit.append(self.proc.pid)
            os.kill(self.proc.pid, sig)
            wait_for_state(self.proc.pid, "T" if sig == signal.SIGSTOP else "Z", 10)  # landed before we go on
        return answer

    monkeypatch.setattr(Simulation, "receive", striking_receive)
    return hit


def process_state(pid: int) -> str:
    """The state letter of /proc/PID/stat (R, S, T, Z...); "" once the process is gone and reaped."""
    try:
        with open(f"/proc/{pid}/stat") as f:
            return f.read().rsplit(")", 1)[1].split()[0]
    except (OSError, IndexError):
        return ""


def wait_for_state(pid: int, states: str, timeout_s: float) -> str:
    """Wait until the process is in one of `states` ("" counts as gone, which satisfies "Z")."""
    t0 = time.monotonic()
    while True:
        state = process_state(pid)
        if (state and state in states) or (not state and "Z" in states):
            return state
        assert time.monotonic() - t0 < timeout_s, f"process {pid} still {state!r}, not in {states!r}"
        time.sleep(0.01)
