"""Shared fixtures: every test that needs EnergyPlus runs the real thing on a short run period."""

from __future__ import annotations

import os
import subprocess

import pytest


def our_processes() -> list[str]:
    """EnergyPlus-side processes still alive (a leak if a test left one)."""
    out = subprocess.run(["pgrep", "-af", "parallel_eplus.eplus_callback"], capture_output=True, text=True)
    return [ln for ln in out.stdout.splitlines() if ln.strip() and "pgrep" not in ln]


def our_pipe_dirs(tmp: str = "/tmp") -> set[str]:
    return {d for d in os.listdir(tmp) if d.startswith("parallel-eplus-") and "episodes" not in d}


@pytest.fixture
def no_leaks():
    """Fails the test if it leaves an EnergyPlus process or a pipe directory behind."""
    before, running = our_pipe_dirs(), set(our_processes())  # a training run may share the machine
    yield
    assert set(our_processes()) - running == set()
    assert our_pipe_dirs() - before == set()
