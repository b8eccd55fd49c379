"""Shared fixtures: every test that needs EnergyPlus runs the real thing on a short run period."""

from __future__ import annotations

import os
import subprocess
from pathlib import Path

import pytest

# Every process this test session starts inherits the marker, so a training run sharing the machine
# is never mistaken for a leak.
os.environ["PARALLEL_EPLUS_TEST_SESSION"] = str(os.getpid())
MARKER = f"PARALLEL_EPLUS_TEST_SESSION={os.getpid()}"


def _started_by_us(pid: str) -> bool:
    try:
        return MARKER.encode() in Path(f"/proc/{pid}/environ").read_bytes().split(b"\0")
    except OSError:  # gone meanwhile, or not ours to read
        return False


def our_processes() -> list[str]:
    """EnergyPlus-side processes this test session started that are still alive (a leak)."""
    out = subprocess.run(["pgrep", "-af", "parallel_eplus.engine.eplus_callback"], capture_output=True, text=True)
    return [ln for ln in out.stdout.splitlines() if ln.strip() and _started_by_us(ln.split()[0])]


def our_pipe_dirs(tmp: str = "/tmp") -> set[str]:
    return {d for d in os.listdir(tmp) if d.startswith("parallel-eplus-") and "episodes" not in d}


@pytest.fixture
def no_leaks():
    """Fails the test if it leaves an EnergyPlus process or a pipe directory behind."""
    before = our_pipe_dirs()
    yield
    assert our_processes() == []
    assert our_pipe_dirs() - before == set()
