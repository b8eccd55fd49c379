"""Shared fixtures: every test that needs EnergyPlus runs the real thing on a short run period."""

from __future__ import annotations

import os
import shutil
import subprocess
import tempfile
from pathlib import Path

import pytest

# Every process this test session starts inherits the marker, so a training run sharing the machine
# is never mistaken for a leak.
os.environ["PARALLEL_EPLUS_TEST_SESSION"] = str(os.getpid())
MARKER = f"PARALLEL_EPLUS_TEST_SESSION={os.getpid()}"

# A temp folder of the session's own, for it and every process it starts: whatever our code leaves in "the
# temp folder" is found there at the end (`pytest_sessionfinish`), whatever else shares /tmp. Ray and pytest's
# own tmp_path stay where they were (Ray's socket paths have a length limit).
_SYSTEM_TMP = os.environ.get("TMPDIR", "/tmp")
os.environ.setdefault("RAY_TMPDIR", _SYSTEM_TMP)
os.environ.setdefault("PYTEST_DEBUG_TEMPROOT", _SYSTEM_TMP)
for _old in Path(_SYSTEM_TMP).glob("pe-tests-*-*"):  # a killed session's folder (its pipes too): its pid is gone
    if _old.name.split("-")[2].isdigit() and not Path(f"/proc/{_old.name.split('-')[2]}").exists():
        shutil.rmtree(_old, ignore_errors=True)
SESSION_TMP = tempfile.mkdtemp(prefix=f"pe-tests-{os.getpid()}-", dir=_SYSTEM_TMP)
os.environ["TMPDIR"] = tempfile.tempdir = SESSION_TMP
LEFT_IN_TMP = ("SB3-", "parallel-eplus-")  # SB3's default logger folders; our pipes and temporary episodes


def pytest_sessionfinish(session, exitstatus):
    """Nothing of ours may stay in the temp folder: fail the session, naming what was left, then tidy up."""
    left = sorted(n for n in os.listdir(SESSION_TMP) if n.startswith(LEFT_IN_TMP))
    if left:
        reporter = session.config.pluginmanager.get_plugin("terminalreporter")
        if reporter is not None:
            reporter.write_line(f"\nFAILED: the tests left in the temp folder: {', '.join(left)}", red=True)
        session.exitstatus = pytest.ExitCode.TESTS_FAILED
    shutil.rmtree(SESSION_TMP, ignore_errors=True)


def _started_by_us(pid: str) -> bool:
    try:
        return MARKER.encode() in Path(f"/proc/{pid}/environ").read_bytes().split(b"\0")
    except OSError:  # gone meanwhile, or not ours to read
        return False


def our_processes() -> list[str]:
    """EnergyPlus-side processes this test session started that are still alive (a leak)."""
    out = subprocess.run(["pgrep", "-af", "parallel_eplus.engine.eplus_side.callback"], capture_output=True, text=True)
    return [ln for ln in out.stdout.splitlines() if ln.strip() and _started_by_us(ln.split()[0])]


def _held_by_another_run(path: str) -> bool:
    """Whether a process outside this test session has a file in `path` open: the pipes of a training
    run sharing the machine, which are not ours to count."""
    prefix = path.rstrip("/") + "/"
    for proc in Path("/proc").iterdir():
        if not proc.name.isdigit() or int(proc.name) == os.getpid() or _started_by_us(proc.name):
            continue
        try:
            if any(os.readlink(fd).startswith(prefix) for fd in (proc / "fd").iterdir()):
                return True
        except OSError:  # gone meanwhile, or not ours to read
            continue
    return False


def _owned_by_another_run(path: str) -> bool:
    """Whether the directory names its owner (engine/pipes/leftovers.py) and that owner is not this session's."""
    try:
        pid = (Path(path) / "owner").read_text().split()[0]
    except (OSError, IndexError):
        return False
    return int(pid) != os.getpid() and not _started_by_us(pid)


def our_pipe_dirs(tmp: str | None = None) -> set[str]:
    """Pipe directories under `tmp` (a `parallel-eplus-*` folder with an `act` FIFO), less those of
    another run on the machine: named as another process's, or held open by one."""
    tmp = tmp or tempfile.gettempdir()
    if not os.path.isdir(tmp):  # the session's own, removed at its end (an interrupted session tears down late)
        return set()
    names = {
        d for d in os.listdir(tmp) if d.startswith("parallel-eplus-") and os.path.exists(os.path.join(tmp, d, "act"))
    }
    return {
        d for d in names
        if not _owned_by_another_run(os.path.join(tmp, d)) and not _held_by_another_run(os.path.join(tmp, d))
    }  # fmt: skip


@pytest.fixture
def no_leaks():
    """Fails the test if it leaves an EnergyPlus process or a pipe directory behind."""
    before = our_pipe_dirs()
    yield
    assert our_processes() == []
    assert our_pipe_dirs() - before == set()


@pytest.fixture
def broken_weather(tmp_path) -> Path:
    """An EPW cut after its header: EnergyPlus starts, then stops on its first weather line."""
    from parallel_eplus.buildings.weather.files import resolve_weather

    broken = tmp_path / "Broken.epw"
    broken.write_text("".join(resolve_weather("CA").read_text(encoding="latin-1").splitlines(True)[:8]))
    return broken
