"""The wire between the env and EnergyPlus: a private pair of named pipes carrying float frames (pipes/frames.py).

The env's end opens both FIFOs read-write, so opening never blocks on a child that died before opening
its end; child death is noticed through a pidfd (or a short poll) instead of waiting for EOF.
"""

from __future__ import annotations

import contextlib
import os
import select
import shutil
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

from parallel_eplus.engine.pipes import leftovers
from parallel_eplus.engine.pipes.frames import FrameReader, parse
from parallel_eplus.engine.pipes.spin import SPIN_S


class PipePair:
    """Two FIFOs in a private 0700 directory: `act` (env -> EnergyPlus) and `obs` (EnergyPlus -> env).

    Each instance makes its own directory with mkdtemp, so names never collide however many envs run
    in one process or on one machine. `close()` removes the FIFOs and the directory; the directory names
    its owner, so one left by a killed process is swept later (leftovers.py).
    """

    def __init__(self, parent_dir: str | os.PathLike | None = None):
        leftovers.sweep_once()
        self.dir = Path(tempfile.mkdtemp(prefix=f"{leftovers.PREFIX}{os.getpid()}-", dir=parent_dir))
        os.chmod(self.dir, 0o700)
        leftovers.write_owner(self.dir)
        self.act_path = self.dir / "act"
        self.obs_path = self.dir / "obs"
        os.mkfifo(self.act_path, 0o600)
        os.mkfifo(self.obs_path, 0o600)
        self.act_fd = os.open(self.act_path, os.O_RDWR)
        self.obs_fd = os.open(self.obs_path, os.O_RDWR | os.O_NONBLOCK)
        self._obs = FrameReader(self.obs_fd)
        self._pidfd: int | None = None
        self._exit_fd: int | None = None
        self._alive: Callable[[], bool] = lambda: True
        self._deadline = 0.0  # of the frame being read (time.monotonic)

    def watch(self, pid: int, alive: Callable[[], bool], exit_fd: int | None = None) -> None:
        """Wake reads when the process on the other end exits, or with `exit_fd` (not ours to close) when that
        becomes readable: a long-lived process's answer that its episode is over (warm_process.py)."""
        self._close_pidfd()
        self._alive = alive
        self._exit_fd = exit_fd
        if exit_fd is not None:
            return
        try:
            self._pidfd = os.pidfd_open(pid)
        except (AttributeError, OSError):  # pragma: no cover - kernels without pidfd
            self._pidfd = None

    def drain(self) -> None:
        """Discard bytes left by a previous simulation, so a new one starts on a clean stream."""
        self._obs.clear()
        for fd in (self.obs_fd, self.act_fd):
            blocking = os.get_blocking(fd)
            os.set_blocking(fd, False)
            try:
                while os.read(fd, 65536):
                    pass
            except BlockingIOError:
                pass
            finally:
                os.set_blocking(fd, blocking)

    def send(self, frame: bytes) -> None:
        os.write(self.act_fd, frame)

    @property
    def _watched(self) -> int | None:
        """The fd readable once the other end is done: `exit_fd`, or the child's pidfd."""
        return self._pidfd if self._exit_fd is None else self._exit_fd

    def fds(self) -> list[int]:
        """What becomes readable when the next frame arrives or the child exits: for a select over many pipes."""
        return [self.obs_fd] if self._watched is None else [self.obs_fd, self._watched]

    @property
    def watches_exit(self) -> bool:
        """Whether `fds()` includes a pidfd or an exit fd, so a select wakes when the child is done (Linux >= 5.3)."""
        return self._watched is not None

    def has_frame(self) -> bool:
        """A whole frame is already read and waiting (no select would report it)."""
        return parse(self._obs.buf) is not None

    def recv(self, timeout: float, spin_s: float = SPIN_S) -> tuple[int, np.ndarray]:
        """Next frame from EnergyPlus. Raises TimeoutError or ChildProcessError, never returns zeros."""
        return self.recv_by(time.monotonic() + timeout, spin_s)

    def recv_by(self, deadline: float, spin_s: float = SPIN_S) -> tuple[int, np.ndarray]:
        """`recv`, due by `deadline` (time.monotonic)."""
        self._deadline = deadline
        # The obs FIFO is held open for writing by us too, so it never reads EOF; death comes via pidfd.
        return self._obs.read(self._wait_readable, spin_s)

    def _wait_readable(self, got: int) -> None:
        deadline = self._deadline
        fds = self.fds()
        while True:
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                cut = f" ({got} bytes of a frame so far)" if got else ""
                raise TimeoutError(f"no data from EnergyPlus{cut}")
            slice_s = remaining if self.watches_exit else min(remaining, 0.2)
            ready, _, _ = select.select(fds, [], [], slice_s)
            if self.obs_fd in ready:
                return
            if ready or not self._alive():
                if self._has_data():  # a last frame written just before the exit
                    return
                where = f" mid-frame ({got} bytes in)" if got else ""
                raise ChildProcessError(f"EnergyPlus process exited{where}")

    def wait_exit(self, timeout: float) -> bool | None:
        """Wait for the watched process to exit (no sleep-polling); False on timeout, None without pidfd."""
        if self._watched is None:
            return None
        ready, _, _ = select.select([self._watched], [], [], timeout)
        return bool(ready)

    def _has_data(self) -> bool:
        ready, _, _ = select.select([self.obs_fd], [], [], 0)
        return bool(ready)

    def _close_pidfd(self) -> None:
        if self._pidfd is not None:
            os.close(self._pidfd)
            self._pidfd = None

    def close(self) -> None:
        self._close_pidfd()
        for fd in (self.act_fd, self.obs_fd):
            with contextlib.suppress(OSError):
                os.close(fd)
        self.act_fd = self.obs_fd = -1
        shutil.rmtree(self.dir, ignore_errors=True)

    def __del__(self):
        if getattr(self, "act_fd", -1) >= 0:
            self.close()
