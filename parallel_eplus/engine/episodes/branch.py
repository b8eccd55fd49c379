"""Branches of a running episode, our side (issue 89, the oracle): forks of its EnergyPlus at the awaited action.

`Branches` talks to an episode started with `SimulationConfig.branching` (engine/eplus_side/branch.py): `run` asks
its process to fork once per action sequence, up to `parallel` children at a time, and returns each child's
observation frames over its rows (None for a child that failed or overran its deadline); `follow` plays one whose
every action the caller computes from its last observation (a rule in closed loop). Call it only while the
episode awaits an action (after an observation and before the action is sent); the episode's own state is never
touched. Every child is ended and its directory removed before `run` returns, on an error and on Ctrl-C too; the
children die with the episode's process in any case (PR_SET_PDEATHSIG).
"""

from __future__ import annotations

import contextlib
import json
import logging
import os
import select
import shutil
import signal
import tempfile
import time
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from parallel_eplus.engine.pipes import frames
from parallel_eplus.engine.pipes.branching import ANSWERS, LOG, REQUESTS, ROWS
from parallel_eplus.engine.pipes.pipe import PipePair
from parallel_eplus.errors import ProtocolError

log = logging.getLogger(__name__)


class BranchError(RuntimeError):
    """The episode's process stopped answering branch requests (it died or hung)."""


class Branches:
    """Forks of one branching episode; `pipe_dir`: its pipe directory (its FIFOs are there), `width`: values per
    observation frame (time fields and sensors)."""

    def __init__(self, pipe_dir: Path, width: int, alive, parallel: int = 2, timeout_s: float = 120.0):
        """`alive()`: whether the episode's process still runs; `timeout_s`: for one child to play its rows."""
        self.width, self.alive, self.parallel, self.timeout_s = width, alive, max(1, parallel), timeout_s
        self.requests = os.open(pipe_dir / REQUESTS, os.O_WRONLY | os.O_NONBLOCK)
        self.answers = os.open(pipe_dir / ANSWERS, os.O_RDONLY | os.O_NONBLOCK)
        self.scratch = Path(tempfile.mkdtemp(prefix="parallel-eplus-branches-"))
        self._buf = b""
        self._next_id = 0
        self.forks = 0
        self.failed = 0

    def run(self, sequences: Sequence[np.ndarray]) -> list[np.ndarray | None]:
        """Each sequence [T, A] of physical actions (the awaited action first) played in a fork of its own: its
        observation frames [T, width] (fewer where the run period ends first), or None where the child failed."""
        results: list[np.ndarray | None] = [None] * len(sequences)
        todo = list(range(len(sequences)))
        running: dict[int, dict] = {}  # request id -> {"k", "dir", "pid", "pidfd", "due"}
        try:
            while todo or running:
                while todo and len(running) < self.parallel:
                    k = todo.pop(0)
                    running[self._request(sequences[k])] = {"k": k, "pid": None, "pidfd": None}
                    running[self._next_id - 1]["dir"] = self.scratch / str(self._next_id - 1)
                    running[self._next_id - 1]["due"] = time.monotonic() + self.timeout_s
                for rid, code in self._answers(running):
                    child = running.pop(rid)
                    if child["pidfd"] is not None:
                        os.close(child["pidfd"])
                    results[child["k"]] = self._rows(child["dir"], code)
                    shutil.rmtree(child["dir"], ignore_errors=True)
                now = time.monotonic()
                for rid in [r for r, c in running.items() if c["due"] < now]:
                    log.warning("a branch ran past %.0f s; killed", self.timeout_s)
                    self._kill(running.pop(rid))
                    self.failed += 1
        finally:
            for child in running.values():
                self._kill(child)
        return results

    def follow(self, first, policy, steps: int, step_timeout_s: float = 60.0) -> tuple[np.ndarray, np.ndarray] | None:
        """One branch whose actions come from `policy(frame values) -> action` (physical units) step by step, the
        awaited one being `first`, over `steps` steps (fewer where the run period ends): (its frames [T, width],
        the actions it took [T, A]), or None where it failed. A closed-loop candidate: a rule played from here."""
        pipes, child = PipePair(), None
        rid = self._request(None, {"obs": str(pipes.obs_path), "act": str(pipes.act_path)})
        running = {rid: {"k": 0, "pid": None, "pidfd": None, "dir": self.scratch / str(rid)}}
        rows, actions, action = [], [], np.asarray(first, float)
        try:
            deadline = time.monotonic() + self.timeout_s
            while running[rid]["pid"] is None:
                if self._answers(running) or time.monotonic() > deadline:
                    raise BranchError("a followed branch ended before it started")
            child = running[rid]
            pipes.watch(child["pid"], self.alive)  # its own pidfd: a reading wakes when the branch dies
            for t in range(steps):
                pipes.send(frames.encode(action))
                actions.append(action)
                code, values = pipes.recv(step_timeout_s, 0.0)
                if code == frames.ERROR:
                    raise BranchError(f"EnergyPlus failed in a followed branch (status {values[:1]})")
                rows.append(np.array(values))
                if code == frames.END:
                    break
                if t + 1 < steps:
                    action = np.asarray(policy(values), float)
        except (BranchError, TimeoutError, ChildProcessError, ProtocolError) as e:
            self.failed += 1
            log.warning("a followed branch failed (%s); it counts as infinitely costly", e)
            return None
        finally:
            self._kill(child or running[rid])
            pipes.close()
        return np.array(rows), np.array(actions)

    def _request(self, actions: np.ndarray | None, pipes: dict | None = None) -> int:
        rid = self._next_id
        self._next_id += 1
        here = self.scratch / str(rid)
        here.mkdir()
        what = pipes if pipes is not None else {"actions": np.asarray(actions, float).tolist()}
        line = json.dumps({"id": rid, "dir": str(here), **what}) + "\n"
        data = line.encode()
        while data:  # a long request may not fit the FIFO at once: the episode reads it while we write
            try:
                data = data[os.write(self.requests, data) :]
            except BlockingIOError:
                if not self.alive():
                    raise BranchError("the episode's EnergyPlus died") from None
                select.select([], [self.requests], [], 1.0)
        self.forks += 1
        return rid

    def _answers(self, running: dict[int, dict]) -> list[tuple[int, int]]:
        """Wait for answers (up to 1 s); the (request id, exit code) of the children that ended."""
        ready, _, _ = select.select([self.answers], [], [], 1.0)
        if not ready:
            if not self.alive():
                raise BranchError("the episode's EnergyPlus died while its branches ran")
            return []
        with contextlib.suppress(BlockingIOError):
            chunk = os.read(self.answers, 65536)
            if not chunk:
                raise BranchError("the episode's EnergyPlus closed its branch answers")
            self._buf += chunk
        ended = []
        by_pid = {c["pid"]: rid for rid, c in running.items() if c["pid"] is not None}
        while b"\n" in self._buf:
            line, self._buf = self._buf.split(b"\n", 1)
            words = line.decode().split()
            if words[0] == "pid" and int(words[1]) in running:
                child = running[int(words[1])]
                child["pid"] = int(words[2])
                with contextlib.suppress(ProcessLookupError):
                    child["pidfd"] = os.pidfd_open(child["pid"])
                by_pid[child["pid"]] = int(words[1])
            elif words[0] == "done" and int(words[1]) in by_pid:
                ended.append((by_pid.pop(int(words[1])), int(words[2])))
        return ended

    def _rows(self, here: Path, code: int) -> np.ndarray | None:
        path = here / ROWS
        if code != 0 or not path.is_file():
            self.failed += 1
            tail = (here / LOG).read_text(errors="replace")[-600:] if (here / LOG).is_file() else ""
            log.warning("a branch failed (exit code %s); it counts as infinitely costly. Its log ends: %s", code,
                        tail.strip() or "(empty)")  # fmt: skip
            return None
        values = np.fromfile(path, "<f8")
        return values.reshape(-1, self.width)

    def _kill(self, child: dict) -> None:
        """End a child (the episode reaps it and answers; a late answer is ignored) and remove its directory."""
        if child.get("pidfd") is not None:
            with contextlib.suppress(OSError):
                signal.pidfd_send_signal(child["pidfd"], signal.SIGKILL)
            os.close(child["pidfd"])
            child["pidfd"] = None
        shutil.rmtree(child["dir"], ignore_errors=True)

    def close(self) -> None:
        for fd in (self.requests, self.answers):
            with contextlib.suppress(OSError):
                os.close(fd)
        self.requests = self.answers = -1
        shutil.rmtree(self.scratch, ignore_errors=True)

    def __del__(self):
        if getattr(self, "requests", -1) >= 0:
            self.close()


def frame_width(sensors: int) -> int:
    """Values per branch row: the observation frame's."""
    return frames.TIME_FIELDS + sensors
