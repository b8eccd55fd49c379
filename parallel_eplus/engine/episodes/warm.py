"""A long-lived EnergyPlus-side process that runs episode after episode, each in a new API state (issue 39).

A process per episode paid, each time, Python's start-up and imports (~0.3 s of CPU) and the page faults of a
fresh address space: EnergyPlus allocates ~200 MB for its state, and in a new process (or a fork) every page of
it is faulted in again. Measured on the data center, a one-day episode from the first allocation to its last step:
in a process that has run one before 0.15-0.33 s, in a fresh fork of a warm interpreter 0.84 s, the new state
alone 0.46 s of it (docs/speed.md). A process that stays reuses its memory, as EnergyPlus alone does when it
runs one period after another with a new state each time (bench/alone.py).

Protocol: one JSON request a line on its stdin (`{"argv": [...], "log": path}`), run as `eplus_callback.main(argv)`
with its output in `log` (its side: engine/eplus_side/warm.py); one line back on its stdout when the episode is over
(`done CODE`). Our side watches that pipe: readable means the episode is over or the process died (EOF). The process
exits when its stdin closes (we closed it, exited, or were killed); an episode of a dead env fails at its pipes first.

    python -m parallel_eplus.engine.eplus_side.callback --serve --pipes DIR   # DIR: the pipes it serves, for `clean`
"""

from __future__ import annotations

import contextlib
import json
import os
import select
import subprocess
import sys
from pathlib import Path


def engine_side_env() -> dict[str, str]:
    """The EnergyPlus-side process's environment: ours, marked so that importing the package skips Gymnasium."""
    from parallel_eplus import ENGINE_SIDE

    return {**os.environ, ENGINE_SIDE: "1"}


class WarmProcess:
    """One long-lived EnergyPlus-side process, started on first use and again after it was killed."""

    def __init__(self, start_timeout_s: float = 60.0):
        self.start_timeout_s = start_timeout_s
        self.proc: subprocess.Popen | None = None

    def start(self, pipe_dir: Path) -> None:
        # The pipes it serves name its owner: `parallel-eplus clean` finds it if its owner dies
        # (engine/pipes/leftovers.py).
        cmd = [sys.executable, "-m", "parallel_eplus.engine.eplus_side.callback", "--serve", "--pipes", str(pipe_dir)]
        self.proc = subprocess.Popen(
            cmd,
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            stderr=subprocess.DEVNULL,
            start_new_session=True,
            env=engine_side_env(),
        )  # its own session, as the episodes' processes had: Ctrl-C reaches the learner, which closes us
        os.set_blocking(self.proc.stdout.fileno(), False)

    def run(self, argv: list[str], log_path: Path, pipe_dir: Path) -> Episode:
        """Start one episode (`eplus_callback.main(argv)`, its output in `log_path`, over the pipes in `pipe_dir`)
        and return at once."""
        request = json.dumps({"argv": argv, "log": str(log_path)}).encode() + b"\n"
        for attempt in range(2):  # a process that died while idle is replaced once
            if self.proc is None or self.proc.poll() is not None:
                self.close()
                self.start(pipe_dir)
            try:
                self.proc.stdin.write(request)
                self.proc.stdin.flush()
                return Episode(self)
            except BrokenPipeError:
                if attempt:
                    raise
                self.close()
        raise AssertionError("unreachable")

    def close(self) -> None:
        """End it now. Between episodes it holds nothing worth a graceful exit (each episode's files are closed when
        it answers), and its interpreter's exit took ~0.1 s of the env's `close()` (issue 39); inside an episode
        it is killed anyway."""
        proc, self.proc = self.proc, None
        if proc is None:
            return
        with contextlib.suppress(OSError):
            proc.stdin.close()
        proc.kill()
        proc.wait()
        proc.stdout.close()


class Episode:
    """One episode in a WarmProcess, with what engine/episodes/process.py uses of `subprocess.Popen`: `pid` (the
    process's, for a pidfd-less watch), `exit_fd` (readable once the episode is over), `poll`, `wait`, `kill`."""

    def __init__(self, owner: WarmProcess):
        self.owner = owner
        self.proc = owner.proc
        self.pid = self.proc.pid
        self.exit_fd = self.proc.stdout.fileno()
        self.returncode: int | None = None
        self._buf = b""

    def poll(self) -> int | None:
        if self.returncode is None:
            self._read()
        return self.returncode

    def _read(self) -> None:
        """Take what the process has answered: `done CODE`, or EOF (it died)."""
        while self.returncode is None:
            try:
                chunk = os.read(self.exit_fd, 256)
            except BlockingIOError:
                if self.proc.poll() is not None:  # died without closing its stdout (cannot, but be sure)
                    self.returncode = -9
                return
            if not chunk:
                self.returncode = self.proc.wait()
                return
            self._buf += chunk
            if b"\n" in self._buf:
                line, _, _ = self._buf.partition(b"\n")
                self.returncode = int(line.split()[1]) if line.startswith(b"done ") else -1
                if self.returncode < 0:  # not our protocol: do not trust the process with another episode
                    self.kill()

    def wait(self, timeout: float | None = None) -> int:
        if self.poll() is None:
            if not select.select([self.exit_fd], [], [], timeout)[0]:
                raise subprocess.TimeoutExpired(f"pid {self.pid}", timeout or 0.0)
            return self.wait(timeout)
        return self.returncode

    def kill(self) -> None:
        """End the episode now: the process with it (the next episode starts a new one)."""
        if self.owner.proc is self.proc:
            self.proc.kill()
            self.proc.wait()
            self.owner.close()
        if self.returncode is None:
            self.returncode = -9
