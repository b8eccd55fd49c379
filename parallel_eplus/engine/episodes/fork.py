"""Forked episodes, our side (issue 39): templates parked at the first control step, one episode forked per request.

A template (fork_side.py) is one EnergyPlus-side process that has read its inputs, sized and warmed up for one model,
weather file and run period, and waits at the run period's first control step. An episode of that weather is a
fork of it: its input processing, sizing and warm-up are paid once per template, not per episode, and a child
touches only what its episode writes (copy on write). The child equals a cold episode bit for bit
(tests/test_fork.py): the same state, reached by the same code, the same files in its directory.

`Templates` keeps one per weather file of a worker's rotation (the model and run period are the worker's), started
on first use and replaced when it dies or hangs; episodes that cannot share one (weather noise: a new file each
episode) start as before (prepared.py, warm_process.py). `ForkedEpisode` is a child as engine/episodes/process.py sees a
process: its pid (watched by pidfd: any process's, not only our children's), `poll`, `wait`, `kill`.
"""

from __future__ import annotations

import contextlib
import json
import logging
import os
import select
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

from parallel_eplus.engine.episodes.warm import engine_side_env

log = logging.getLogger(__name__)
ANSWER_S = 10.0  # for a parked template to answer a fork request (it takes milliseconds): longer means hung


def template_env() -> dict[str, str]:
    """A template's environment: no thread pool to lose in a fork (numpy's OpenBLAS), and malloc's heap in
    transparent huge pages (glibc >= 2.35; older ones ignore it): a fork copies far fewer page-table entries
    (its system time 7 -> 1 ms) and a child's page faults cost less (a 1-day episode's 32 -> 24 ms of system time)."""
    tunables = ":".join(filter(None, [os.environ.get("GLIBC_TUNABLES"), "glibc.malloc.hugetlb=1"]))
    return {**engine_side_env(), "OPENBLAS_NUM_THREADS": "1", "GLIBC_TUNABLES": tunables}


class ForkFailed(RuntimeError):
    """The template died or hung: it is replaced, the episode starts as without one."""


class Template:
    """One parked EnergyPlus for one weather file, forked per episode."""

    def __init__(self, epw: Path, model: bytes, model_name: str, args: list[str], pipe_dir: Path, timeout_s: float):
        """`args`: the EnergyPlus side's arguments every episode shares (steps, initial action, the C bridge);
        `pipe_dir`: a pipe directory of its worker (the template's own directory goes in it, and it names its owner
        for `parallel-eplus clean`)."""
        self.epw = epw
        self.dir = Path(tempfile.mkdtemp(prefix="template-", dir=pipe_dir))
        (self.dir / model_name).write_bytes(model)
        cmd = [sys.executable, "-m", "parallel_eplus.engine.eplus_side.callback", "--template",
               "--pipes", str(pipe_dir), "--idf", model_name, "--epw", str(epw),
               "--output-dir", ".", *args]  # fmt: skip
        with open(self.dir / "energyplus.log", "wb") as logf:
            self.proc = subprocess.Popen(
                cmd, cwd=self.dir, stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=logf, start_new_session=True,
                env=template_env(),
            )  # fmt: skip
        os.set_blocking(self.proc.stdout.fileno(), False)
        self.deadline = time.monotonic() + timeout_s  # to park by: past it, it hung
        self.is_parked = False
        self.codes: dict[int, int] = {}  # children's exit codes, as it answered them
        self._pending: list[ForkedEpisode] = []  # forks asked for, their pids not answered yet (answers come in order)
        self._failed = False  # a fork request went unanswered: it hung
        self._buf = b""
        self._eof = False  # it answers no more: it died, or we closed it

    def _read(self, timeout: float = 0.0) -> None:
        """Take what the template has answered, waiting up to `timeout` for something."""
        if self._eof:
            return
        fd = self.proc.stdout.fileno()
        if not select.select([fd], [], [], timeout)[0]:
            return
        while True:
            try:
                chunk = os.read(fd, 65536)
            except BlockingIOError:
                break
            if not chunk:
                self._eof = True
                break
            self._buf += chunk
        while b"\n" in self._buf:
            line, self._buf = self._buf.split(b"\n", 1)
            words = line.split()
            if words == [b"parked"]:
                self.is_parked = True
            elif words[:1] == [b"pid"] and self._pending:
                self._pending.pop(0)._started(int(words[1]))
            elif words[:1] == [b"done"]:
                self.codes[int(words[1])] = int(words[2])

    def alive(self) -> bool:
        self._read()
        return not self._eof and self.proc.poll() is None

    def parked(self) -> bool:
        return self.alive() and self.is_parked

    def hung(self) -> bool:
        return self._failed or (not self.is_parked and time.monotonic() > self.deadline)

    def wait_parked(self) -> bool:
        """Wait for it to park, by its deadline: False if it died or hung first."""
        while self.alive() and not self.is_parked and time.monotonic() < self.deadline:
            self._read(min(0.5, max(0.0, self.deadline - time.monotonic())))
        return self.parked()

    def fork(self, request: dict) -> ForkedEpisode:
        """Ask for an episode (`request`: its directory, log, pipes, spin) without waiting: its pid comes with the
        template's answer (`ForkedEpisode.started`; the fork itself, ~7 ms of page tables, runs beside us).
        ForkFailed if the template is gone."""
        try:
            self.proc.stdin.write(json.dumps(request).encode() + b"\n")
            self.proc.stdin.flush()
        except (BrokenPipeError, OSError, ValueError) as e:
            raise ForkFailed(f"the template for {self.epw.name} is gone ({e})") from e
        episode = ForkedEpisode(self)
        self._pending.append(episode)
        return episode

    def answer(self, episode: ForkedEpisode, timeout: float) -> None:
        """Wait for `episode`'s pid: ForkFailed if the template died or hung first."""
        deadline = time.monotonic() + timeout
        while episode._pid is None:
            if self._eof or time.monotonic() > deadline:
                self._failed = True
                raise ForkFailed(f"the template for {self.epw.name} {'died' if self._eof else 'hung'}")
            self._read(max(0.0, deadline - time.monotonic()))

    def close(self) -> None:
        """End it and remove its directory. Killed first: its children are ours to end (a running episode outlives
        a template that failed); only its owner's death, closing its stdin, makes it end them."""
        if self.proc.stdout.closed:
            return
        self._eof = True
        self.proc.kill()
        self.proc.wait()
        with contextlib.suppress(OSError):
            self.proc.stdin.close()
        self.proc.stdout.close()
        shutil.rmtree(self.dir, ignore_errors=True)


class Templates:
    """A worker's templates, one per weather file, started on first use and replaced when they die or hang."""

    def __init__(self, model: Callable[[], bytes], model_name: str, args: list[str], timeout_s: float):
        """`model`: the episode's model file's bytes (the same for every episode); `args`: as Template's."""
        self.model, self.model_name, self.args, self.timeout_s = model, model_name, args, timeout_s
        self.by_epw: dict[Path, Template] = {}

    def get(self, epw: Path, pipe_dir: Path, wait: bool) -> Template | None:
        """The parked template for `epw` (started now if there is none or it died or hung); with `wait`, waited
        for; None where there is none parked (yet, or it failed: the episode then starts without it)."""
        t = self.by_epw.get(epw)
        if t is not None and (not t.alive() or t.hung()):
            log.warning("the parked EnergyPlus for %s %s; starting another", epw.name, "hung" if t.alive() else "died")
            self.drop(t)
            t = None
        if t is None:
            t = self.by_epw[epw] = Template(epw, self.model(), self.model_name, self.args, pipe_dir, self.timeout_s)
        if t.parked() or (wait and t.wait_parked()):
            return t
        if wait:  # it failed to park: the episode starts without it, and reports what failed as a cold one does
            self.drop(t)
        return None

    def drop(self, t: Template) -> None:
        if self.by_epw.get(t.epw) is t:
            del self.by_epw[t.epw]
        t.close()

    def close(self) -> None:
        for t in list(self.by_epw.values()):
            self.drop(t)


class ForkedEpisode:
    """A forked child as engine/episodes/process.py uses a process: `pid`, `poll`, `wait`, `kill` (not ours to reap: its
    template reaps it and answers its code; `poll` says -1 where the template has not answered yet). Its pid is
    known once the template answered (`started`); until then it counts as starting up."""

    exit_fd = None  # the pipes watch its pid by a pidfd of their own

    def __init__(self, template: Template):
        self.template = template
        self._pid: int | None = None  # known once the template answered
        self._pidfd: int | None = None
        self.returncode: int | None = None

    @property
    def pid(self) -> int | None:
        """Its pid, waited for if the template has not answered yet (None: it failed)."""
        self.started()
        return self._pid

    def _started(self, pid: int) -> None:
        self._pid = pid
        with contextlib.suppress(ProcessLookupError):  # else it ended (and was reaped) already
            self._pidfd = os.pidfd_open(pid)

    def started(self, timeout: float | None = None) -> bool:
        """Its pid, waited for up to `timeout` (default ANSWER_S): False if the template died or hung first (the
        episode then counts as ended)."""
        if self._pid is None and self.returncode is None:
            try:
                self.template.answer(self, ANSWER_S if timeout is None else timeout)
            except ForkFailed as e:
                log.warning("%s before it answered a fork", e)
                self.returncode = -1
        return self._pid is not None

    def poll(self) -> int | None:
        if self.returncode is not None:
            return self.returncode
        if self._pid is None:
            if not self.template.alive() and self._pid is None:  # (alive() takes its answers)
                self.returncode = -1
            return self.returncode
        if self._pidfd is None or select.select([self._pidfd], [], [], 0)[0]:
            self._ended()
        return self.returncode

    def _ended(self) -> None:
        with contextlib.suppress(ValueError, OSError):
            self.template._read()
        self.returncode = self.template.codes.pop(self._pid, -1)
        if self._pidfd is not None:
            os.close(self._pidfd)
            self._pidfd = None

    def wait(self, timeout: float | None = None) -> int:
        running = self.poll() is None and self.started(timeout) and self.poll() is None
        if running and not select.select([self._pidfd], [], [], timeout)[0]:
            raise subprocess.TimeoutExpired(f"pid {self._pid}", timeout or 0.0)
        return self.poll()

    def kill(self) -> None:
        self.started()  # to kill it, its pid: a fork asked for may still be under way
        if self._pidfd is not None:
            with contextlib.suppress(ProcessLookupError):
                signal.pidfd_send_signal(self._pidfd, signal.SIGKILL)
