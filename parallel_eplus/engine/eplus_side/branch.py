"""Branches of a running episode, the EnergyPlus side (issue 89, the oracle): forks of the process at a control step.

An episode run with `--branching` is an ordinary episode (its pipes, its frames, the Python bridge at every step)
that, wherever it awaits an action, also serves requests to fork itself: each child is a copy of the simulation at
that point (copy on write, as engine/eplus_side/fork.py's templates are copied at the first control step), plays
the action rows it was given (physical units, one per control step, from the awaited action on) and writes the
observation frame of each step (time and sensors, `frames.TIME_FIELDS` + sensors float64 values a row) to
`rows.f8` in its own directory, then exits. A followed branch (its request names a pipe pair instead of rows)
takes each action from the env as an episode does, the env's controller answering each observation (a rule, played
in closed loop), until the env ends it. A child that fails (EnergyPlus's fatal error, a crash) exits with a
non-zero code and writes no rows. The parent never applies a branch's action: the env decides, then sends it.

Its FIFOs, made by the parent beside its act pipe (`REQUESTS`, `ANSWERS`, in the env's private pipe directory,
removed with it): a JSON line per request, `{"id", "dir", "actions"}` or `{"id", "dir", "obs", "act"}`; answers
`pid ID PID` per fork and `done PID CODE` per child reaped. Every child dies with its parent (PR_SET_PDEATHSIG),
and the parent dies when the env goes (its act pipe reads EOF): nothing outlives the env. Our side:
engine/episodes/branch.py.
"""

from __future__ import annotations

import contextlib
import ctypes
import json
import os
import select
import signal
import sys
import traceback
from pathlib import Path

import numpy as np

from parallel_eplus.engine.eplus_side.bridge import Bridge
from parallel_eplus.engine.eplus_side.descriptors import own_descriptions, reopened_copy
from parallel_eplus.engine.pipes import frames
from parallel_eplus.engine.pipes.branching import ANSWERS, LOG, REQUESTS, ROWS

_PR_SET_PDEATHSIG = 1
COPIED_OUTPUTS = (".sql",)  # outputs a child may read back (SQLite): copied; any other output goes to /dev/null


class BranchingBridge(Bridge):
    """The Bridge of an episode whose every awaited action may be forked first (`serve`); in a child, the Bridge of
    a branch playing its rows (`script`)."""

    def open_branching(self, pipe_dir: Path) -> None:
        """Make and open the request and answer FIFOs in `pipe_dir` (before observation 0: the env opens them after)."""
        for name in (REQUESTS, ANSWERS):
            os.mkfifo(pipe_dir / name, 0o600)
        self.requests = os.open(pipe_dir / REQUESTS, os.O_RDWR | os.O_NONBLOCK)  # RDWR: opening never blocks
        self.answers = os.open(pipe_dir / ANSWERS, os.O_RDWR)
        self.children: dict[int, int] = {}  # pidfd -> pid
        self.followed = False  # in a followed branch: each action from the env over a pipe pair of its own
        self._lines = b""
        self.script: np.ndarray | None = None  # in a branch: its action rows
        self.rows: list[list[float]] = []

    def _guard(self, state, fn) -> None:
        """In a branch, a failure ends the process at once: EnergyPlus stopped would write its end-of-run files by
        path, into the episode's own directory."""
        self._state = state  # a branch registers its message callback on it (`_become_branch`)
        if self.script is None and not self.followed:
            super()._guard(state, fn)
            return
        try:
            fn(state)
        except BaseException:  # noqa: BLE001 - the env sees the exit code (a followed branch: its pipe closing)
            traceback.print_exc()
            with contextlib.suppress(Exception):
                sys.stdout.flush()
                sys.stderr.flush()
            os._exit(1)

    # -- the parent: requests served while an action is awaited ------------------------------------
    def _take_action(self) -> None:
        if self.script is None and not self.followed:
            self._serve()
        if self.script is not None:  # a branch (forked just now, in `_serve`, or steps since)
            self._next_row()
            return
        super()._take_action()  # the episode's action, or a followed branch's from its own pipe

    def _serve(self) -> None:
        """Fork per request and reap children until the action is there (a child returns from here as a branch)."""
        while not self._actions.buf:
            ready, _, _ = select.select([self.act_fd, self.requests, *self.children], [], [])
            for fd in ready:
                if fd in self.children:
                    self._reap(fd)
            if self.requests in ready:
                with contextlib.suppress(BlockingIOError):
                    self._lines += os.read(self.requests, 65536)
                while b"\n" in self._lines:
                    line, self._lines = self._lines.split(b"\n", 1)
                    if self._fork(json.loads(line)):
                        return  # the child: its branch goes on from the awaited action
            if self.act_fd in ready:
                return

    def _reap(self, fd: int) -> None:
        pid = self.children.pop(fd)
        os.close(fd)
        _, status = os.waitpid(pid, 0)
        self._answer(f"done {pid} {os.waitstatus_to_exitcode(status)}")

    def _answer(self, text: str) -> None:
        os.write(self.answers, (text + "\n").encode())

    def _fork(self, request: dict) -> bool:
        """Fork for `request`; True in the child, set up as its branch."""
        sys.stdout.flush()
        sys.stderr.flush()
        pid = os.fork()
        if pid == 0:
            try:
                self._become_branch(request)
            except BaseException:  # noqa: BLE001 - a child never returns into the parent's loop
                traceback.print_exc()
                os._exit(1)
            return True
        self.children[os.pidfd_open(pid)] = pid
        self._answer(f"pid {request['id']} {pid}")
        return False

    # -- the child ---------------------------------------------------------------------------------
    def _become_branch(self, request: dict) -> None:
        parent = os.getppid()
        ctypes.CDLL(None, use_errno=True).prctl(_PR_SET_PDEATHSIG, signal.SIGKILL, 0, 0, 0)
        if os.getppid() != parent:  # the parent died before the line above
            os._exit(1)
        for fd in [*self.children, self.requests, self.answers, self.act_fd, self.obs_fd]:
            with contextlib.suppress(OSError):
                os.close(fd)
        self.children = {}
        here = Path(request["dir"])
        null = os.open(os.devnull, os.O_RDONLY)
        os.dup2(null, 0)
        os.close(null)
        log = os.open(here / LOG, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)
        os.dup2(log, 1)
        os.dup2(log, 2)
        os.close(log)
        _own_descriptions(here)
        os.chdir(here)
        # EnergyPlus's fatal error would end its run and write its end files by path, into the episode's directory:
        # the branch exits at its first word of it instead
        self._on_message = lambda message: os._exit(1) if message.lstrip().startswith(b"**FATAL") else None
        self.api.runtime.callback_message(self._state, self._on_message)
        self.obs_fd = self.act_fd = -1
        self.dir = here
        if "obs" in request:  # followed: the env answers each observation, as in an episode (its last: END)
            obs_fd = os.open(request["obs"], os.O_WRONLY | os.O_NONBLOCK)
            os.set_blocking(obs_fd, True)
            self.act_fd = os.open(request["act"], os.O_RDONLY | os.O_NONBLOCK)
            self.obs_fd, self.followed = obs_fd, True
            self._wait, self._actions = frames.wait_readable(self.act_fd), frames.FrameReader(self.act_fd)
            self.spin_s = 0.0
            return
        self.script = np.asarray(request["actions"], np.float64)
        self.cursor, self.rows = 0, []

    def _next_row(self) -> None:
        self.awaiting = False
        if self.cursor >= len(self.script):
            self._finish()
        self.action = self.script[self.cursor].tolist()
        self.cursor += 1
        self.pending = True

    def _observe(self, state) -> None:
        if self.script is None:
            super()._observe(state)
            if self.followed and self.done:  # never into EnergyPlus's end of run: its files are the episode's
                os._exit(0)
            return
        if self.awaiting:
            self._next_row()
        self.step += 1
        self.rows.append(self._time(state) + self._read_sensors(state))
        if len(self.rows) >= len(self.script) or self.step >= self.steps:
            self._finish()
        self.awaiting = True

    def _finish(self) -> None:
        """The branch's rows to its directory, and exit (no EnergyPlus teardown: the copy is thrown away)."""
        try:
            tmp = self.dir / (ROWS + ".tmp")
            np.asarray(self.rows, "<f8").tofile(tmp)
            os.replace(tmp, self.dir / ROWS)
            code = 0
        except BaseException:  # noqa: BLE001
            traceback.print_exc()
            code = 1
        with contextlib.suppress(Exception):
            sys.stdout.flush()
            sys.stderr.flush()
        os._exit(code)


def _own_descriptions(here: Path) -> None:
    """Descriptions of the branch's own (descriptors.py): an output goes to /dev/null, except one EnergyPlus may read
    back (`COPIED_OUTPUTS`: SQLite's), copied into `here`."""

    def output(target: Path, flags: int) -> int:
        if target.suffix in COPIED_OUTPUTS:
            return reopened_copy(target, here, flags)
        return os.open(os.devnull, os.O_WRONLY)

    own_descriptions(output)
