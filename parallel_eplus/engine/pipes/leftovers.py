"""Pipe directories and EnergyPlus processes left behind by a process that was killed outright.

A trainer stopped by SIGKILL (the OOM killer, a lost node, `kill -9`) runs no cleanup: its EnergyPlus
processes see their pipe close and exit, but the pipe directories stay. Each directory records its
owner (an `owner` file: PID and the process's start time, so a recycled PID is not mistaken for it);
the first pipe a process makes sweeps directories whose owner is gone, and `parallel-eplus clean`
does the same on demand. A directory whose owner is alive is never touched: other runs share the machine.
"""

from __future__ import annotations

import contextlib
import logging
import os
import shutil
import signal
import tempfile
from dataclasses import dataclass
from pathlib import Path

log = logging.getLogger(__name__)

PREFIX = "parallel-eplus-"
OWNER_FILE = "owner"
CALLBACK_MODULE = "parallel_eplus.engine.eplus_side.callback"
_swept = False


def start_time(pid: int) -> str | None:
    """The process's start time in clock ticks since boot (/proc/PID/stat field 22), None if it is gone."""
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return None
    return stat.rsplit(")", 1)[1].split()[19]  # fields after the command name start at field 3


def write_owner(pipe_dir: Path) -> None:
    pid = os.getpid()
    (pipe_dir / OWNER_FILE).write_text(f"{pid} {start_time(pid)}\n")


def owner_alive(pipe_dir: Path) -> bool | None:
    """True/False for a directory that names its owner; None for one that does not (older versions)."""
    try:
        pid_text, started = (pipe_dir / OWNER_FILE).read_text().split()
        pid = int(pid_text)
    except (OSError, ValueError):
        return None
    return start_time(pid) == started


def pipe_dirs(tmp: str | os.PathLike | None = None) -> list[Path]:
    """Our pipe directories under the temp folder: `parallel-eplus-*` holding an `act` FIFO, or naming an owner (a
    scratch folder of ours, as a Ray evaluation task's: a worker killed by Ray's shutdown runs no cleanup)."""
    root = Path(tmp or tempfile.gettempdir())
    try:
        names = [n for n in os.listdir(root) if n.startswith(PREFIX)]
    except OSError:
        return []
    return sorted(d for n in names if (d := root / n).is_dir() and ((d / "act").exists() or (d / OWNER_FILE).exists()))


def _held_open(pipe_dir: Path) -> bool:
    """Whether any process has a file in `pipe_dir` open (for directories that do not name their owner)."""
    prefix = str(pipe_dir) + "/"
    for proc in Path("/proc").iterdir():
        if not proc.name.isdigit():
            continue
        with contextlib.suppress(OSError):
            if any(os.readlink(fd).startswith(prefix) for fd in (proc / "fd").iterdir()):
                return True
    return False


def stale_pipe_dirs(tmp: str | os.PathLike | None = None, unowned: bool = False) -> list[Path]:
    """Pipe directories whose owner is gone; with `unowned`, also older ones no process has open."""
    stale = []
    for d in pipe_dirs(tmp):
        alive = owner_alive(d)
        if alive is False or (alive is None and unowned and not _held_open(d)):
            stale.append(d)
    return stale


def sweep(tmp: str | os.PathLike | None = None, unowned: bool = False) -> list[Path]:
    """Remove stale pipe directories; returns them."""
    removed = []
    for d in stale_pipe_dirs(tmp, unowned):
        shutil.rmtree(d, ignore_errors=True)
        if not d.exists():
            removed.append(d)
    if removed:
        log.info("removed %d pipe director%s left by processes that are gone", len(removed),
                 "y" if len(removed) == 1 else "ies")  # fmt: skip
    return removed


def sweep_once() -> None:
    """The first pipe a process makes sweeps the temp folder (once per process: it costs a directory scan)."""
    global _swept
    if not _swept:
        _swept = True
        try:
            sweep()
        except OSError as e:  # never let housekeeping stop a run
            log.debug("pipe sweep skipped: %s", e)


@dataclass
class Leftover:
    pid: int
    pipe_dir: Path | None
    command: str


def leftover_processes() -> list[Leftover]:
    """EnergyPlus-side processes of ours whose trainer is gone: their pipe's owner is dead (or, for pipes that
    name no owner, they were re-parented to init)."""
    found = []
    for proc in Path("/proc").iterdir():
        if not proc.name.isdigit():
            continue
        try:
            argv = (proc / "cmdline").read_bytes().split(b"\0")
            ppid = int((proc / "stat").read_text().rsplit(")", 1)[1].split()[1])
        except (OSError, ValueError, IndexError):
            continue
        args = [a.decode(errors="replace") for a in argv if a]
        if CALLBACK_MODULE not in args:
            continue
        pipe_dir = Path(args[args.index("--act-pipe") + 1]).parent if "--act-pipe" in args[:-1] else None
        if "--pipes" in args[:-1]:  # a long-lived one (warm_process.py): the pipes it serves
            pipe_dir = Path(args[args.index("--pipes") + 1])
        alive = owner_alive(pipe_dir) if pipe_dir is not None else None
        orphaned = ppid == 1 or (pipe_dir is not None and not pipe_dir.exists())  # its pipe already swept
        if alive is False or (alive is None and orphaned):
            found.append(Leftover(int(proc.name), pipe_dir, " ".join(args)))
    return found


def kill(leftovers: list[Leftover]) -> None:
    for p in leftovers:
        with contextlib.suppress(ProcessLookupError):
            os.kill(p.pid, signal.SIGKILL)
