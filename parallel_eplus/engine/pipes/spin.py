"""When a side of the pipes spins for its next frame instead of blocking: only where a core is free to spin on.

Both sides' reads (engine/pipes/frames.py's FrameReader, the EnergyPlus side's bridge) busy-wait up to a spin time
before blocking; a spin on a machine with no spare core steals the cycles the other side needs.
"""

from __future__ import annotations

import os

SPIN_S = 0.002  # see engine/pipes/frames.py's FrameReader


def others_running(ours: int) -> int:
    """Runnable tasks on this machine beside `ours` processes of ours: the 1-minute load average less ours."""
    try:
        load = os.getloadavg()[0]
    except OSError:  # pragma: no cover - no load average (not Linux)
        return 0
    return round(max(load - ours, 0.0))


def default_spin_s(processes: int) -> float:
    """The env side spins only when every process of a step has a core of its own, other runs' counted."""
    return SPIN_S if processes + others_running(processes) <= (os.cpu_count() or 1) else 0.0


def auto_spins(workers: int) -> tuple[float, float]:
    """(the env side's spin, EnergyPlus's) for `workers` EnergyPlus processes stepped by one of ours, decided at
    each episode's start: spin only where a core is free to spin on, other runs' load counted.

    The EnergyPlus side spins when each EnergyPlus process has a core (it yields while it does): measured with
    2 workers on 2 cores, EnergyPlus-side spinning gained 10 % while env-side spinning lost 40 % to stolen
    cycles. On a machine already busy with other runs both sides block: a year under a load average of 12-20
    on 2 cores ran at env/raw 1.37 blocking against 1.38-1.52 spinning, on 40 % less CPU (docs/speed.md).
    """
    cores = os.cpu_count() or 1
    others = others_running(workers + 1)
    return (SPIN_S if workers + 1 + others <= cores else 0.0), (SPIN_S if workers + others <= cores else 0.0)
