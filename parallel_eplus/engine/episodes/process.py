"""One EnergyPlus process behind one pipe pair: spawned, answered by a deadline, stopped with nothing left behind.

`Simulation` decides what an episode is (files, actions, reward, records); this module only knows the
process: how it is started, how a frame is awaited against a deadline, and how it ends. `wait_any` serves
many of them as each answers, for the vector env and the evaluation sweep.
"""

from __future__ import annotations

import contextlib
import logging
import math
import os
import select
import subprocess
import sys
import time
from collections.abc import Container, Iterable, Sequence
from pathlib import Path

import numpy as np

from parallel_eplus.engine.episodes.fork import ANSWER_S, ForkedEpisode, Template
from parallel_eplus.engine.episodes.warm import Episode, WarmProcess, engine_side_env
from parallel_eplus.engine.pipes import frames, pipe, spin

log = logging.getLogger(__name__)


class EnergyPlusProcess:
    """The EnergyPlus side of one worker, episode after episode, over one pipe pair kept between episodes."""

    def __init__(self, spin_s: float | None, native_bridge: str | None, siblings: int = 1, warm: bool = False):
        """`spin_s`: how long both sides' reads spin before blocking; None: `spin.auto_spins` for `siblings`
        EnergyPlus processes stepped by this process, decided again at each spawn. `warm`: run episode after episode
        in one long-lived EnergyPlus-side process (warm_process.py); else a new process per episode."""
        self.warm = WarmProcess() if warm else None
        self.auto_spin = spin_s is None
        self.siblings = siblings
        self.spin_s = 0.0 if spin_s is None else spin_s  # how long our reads spin before blocking
        self.child_spin_s = self.spin_s  # the same for EnergyPlus's side
        self.native_bridge = native_bridge
        self.pipes: pipe.PipePair | None = None
        self.proc: subprocess.Popen | Episode | ForkedEpisode | None = None
        self.deadline = math.inf  # when the frame awaited next is overdue (monotonic s)
        self._attached = True  # a forked episode's pid is watched (`attach`)

    def _fresh_pipes(self) -> pipe.PipePair:
        if self.pipes is None:
            self.pipes = pipe.PipePair()
        self.pipes.drain()
        if self.auto_spin:
            self.spin_s, self.child_spin_s = spin.auto_spins(self.siblings)
        return self.pipes

    def fork(self, template: Template, episode_dir: Path, log_path: Path, first_frame_s: float, wait: bool) -> None:
        """Fork the episode from a parked template (fork.py): its first frame is due in `first_frame_s`. With `wait`,
        its pid is waited for and watched now (ForkFailed if the template died or hung); else by `attach`, when the
        episode is handed out (a prepared one: the fork runs beside the episode before it)."""
        p = self._fresh_pipes()
        request = {"dir": str(episode_dir), "log": str(log_path), "obs": str(p.obs_path), "act": str(p.act_path),
                   "spin_us": self.child_spin_s * 1e6}  # fmt: skip
        self.proc = template.fork(request)
        self.deadline = time.monotonic() + first_frame_s
        self._attached = False
        if wait:
            template.answer(self.proc, ANSWER_S)
            self.attach()

    def attach(self) -> None:
        """Watch a forked episode's pid (waited for if the template has not answered yet), before stepping it."""
        if isinstance(self.proc, ForkedEpisode) and not self._attached:
            self._attached = True
            self.proc.started()
            proc = self.proc
            self.pipes.watch(proc.pid or 0, lambda: proc.poll() is None)  # no pid: it failed, seen as exited

    def spawn(self, args: list[str], log_path: Path, first_frame_s: float) -> None:
        """Start EnergyPlus (`eplus_callback` with `args`), not waiting: its first frame is due in `first_frame_s`."""
        self._fresh_pipes()
        argv = [
            "--act-pipe", str(self.pipes.act_path), "--obs-pipe", str(self.pipes.obs_path), *args,
            "--spin-us", str(self.child_spin_s * 1e6),
            *(["--native", self.native_bridge] if self.native_bridge else []),
        ]  # fmt: skip
        if self.warm is not None:
            self.proc = self.warm.run(argv, log_path, self.pipes.dir)
        else:
            with open(log_path, "wb") as logf:
                self.proc = subprocess.Popen(
                    [sys.executable, "-m", "parallel_eplus.engine.eplus_side.callback", *argv],
                    stdin=subprocess.DEVNULL, stdout=logf, stderr=subprocess.STDOUT, env=engine_side_env(),
                    start_new_session=True,  # Ctrl-C reaches the learner, which stops us cleanly
                )  # fmt: skip
        alive = lambda: self.proc is not None and self.proc.poll() is None  # noqa: E731
        self.pipes.watch(self.proc.pid, alive, getattr(self.proc, "exit_fd", None))
        self.deadline = time.monotonic() + first_frame_s

    def send(self, frame: bytes, answer_s: float) -> None:
        """One action frame; its answer is due in `answer_s`."""
        self.pipes.send(frame)
        self.deadline = time.monotonic() + answer_s

    def recv(self) -> tuple[int, np.ndarray]:
        """The frame awaited next, by the deadline: raises TimeoutError, ChildProcessError or ProtocolError."""
        return self.pipes.recv_by(self.deadline, self.spin_s)

    def finish(self, grace_s: float = 30.0) -> None:
        """After the last step: let EnergyPlus write its files and exit, then make sure it has."""
        if self.proc is None:
            return
        exited = True if self.proc.poll() is not None else self.pipes.wait_exit(grace_s)  # (a poll took its answer)
        if exited is None:
            with contextlib.suppress(subprocess.TimeoutExpired):
                exited = self.proc.wait(timeout=grace_s) is not None
        if not exited:
            log.warning("EnergyPlus did not exit within %.0f s of the last step; killing it", grace_s)
        self.kill()

    def pipe_dir(self) -> Path:
        """Its pipe directory (made now if it has none): a template's directory goes in it (fork.py)."""
        if self.pipes is None:
            self.pipes = pipe.PipePair()
        return self.pipes.dir

    def warm_up(self) -> None:
        """Start the long-lived process now, with no episode yet: its start-up and imports then run beside the
        episode before the one it will prepare."""
        if self.warm is not None and self.warm.proc is None:
            if self.pipes is None:
                self.pipes = pipe.PipePair()
            self.warm.start(self.pipes.dir)

    def end_episode(self, grace_s: float = 5.0) -> None:
        """End a running episode early. A long-lived process gets a control frame where EnergyPlus awaits its next
        action (the bridge stops EnergyPlus) and stays for the next episode; one that does not stop in
        `grace_s`, or a process of its own, is killed."""
        if isinstance(self.proc, Episode) and self.running():  # a fork (or a process of its own) is just killed
            with contextlib.suppress(OSError):
                self.pipes.send(frames.encode([], frames.END))  # not an action: the bridge stops EnergyPlus
            with contextlib.suppress(subprocess.TimeoutExpired):
                self.proc.wait(timeout=grace_s)
        self.kill()

    def kill(self) -> None:
        proc, self.proc = self.proc, None
        if proc is None:
            return
        if proc.poll() is None:
            proc.kill()
        proc.wait()

    def has_frame(self) -> bool:
        """A frame is waiting to be read (EnergyPlus parked at a control step), without reading it."""
        p = self.pipes
        return p is not None and (p.has_frame() or bool(select.select([p.obs_fd], [], [], 0)[0]))

    def running(self) -> bool:
        """Whether EnergyPlus is alive (it exits on its own only after its last step)."""
        return self.proc is not None and self.proc.poll() is None

    def close(self) -> None:
        self.kill()
        if self.warm is not None:
            self.warm.close()
        if self.pipes is not None:
            self.pipes.close()
            self.pipes = None


def wait_any(procs: Sequence, indices: Iterable[int], due: Container[int] = ()) -> list[int]:
    """Those of `procs[i]` (i in `indices`; anything with `pipes`, `deadline`, `running`, `spin_s`) with
    something to read: a frame, an exit, or a deadline passed (plus any in `due`). Blocks until one has.

    For pipelining: serve each simulation as soon as it answers instead of waiting for the slowest. Like
    a single read, it polls for the simulations' spin time first (none when they and this process have
    no spare core: see `spin.default_spin_s`).
    """
    indices = list(indices)
    if not indices:
        return []
    spin_until = time.monotonic() + procs[indices[0]].spin_s
    while True:
        now = time.monotonic()
        ready = [
            i for i in indices
            if i in due or procs[i].pipes.has_frame() or procs[i].deadline <= now
            or not (procs[i].pipes.watches_exit or procs[i].running())
        ]  # fmt: skip
        if ready:
            return ready
        fds = {fd: i for i in indices for fd in procs[i].pipes.fds()}
        wait = min(procs[i].deadline for i in indices) - now
        if now < spin_until:
            os.sched_yield()  # let a process on this core go first, as a single simulation's read does
            wait = 0.0
        elif not all(procs[i].pipes.watches_exit for i in indices):
            wait = min(wait, 0.2)  # no pidfd to wake us when a process dies: look every 0.2 s
        readable, _, _ = select.select(list(fds), [], [], None if math.isinf(wait) else wait)
        if readable:
            return sorted({fds[fd] for fd in readable})
