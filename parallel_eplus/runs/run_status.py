"""runs/<name>/status.json: what a training run is doing, kept current by the trainer, read by `parallel-eplus runs`.

Written atomically (io.py) when the run starts, every `EVERY_S` seconds while it learns and when it ends: the
state (running, then finished, stopped or failed), the process that runs it (pid, host and the process's start
time, so a recycled pid is not mistaken for it; the Ray Tune trial from PARALLEL_EPLUS_TRIAL), steps done and
planned, and wall time over every session of a resumed run. A trainer killed outright (SIGKILL, OOM) leaves
"running" with a dead pid behind: the registry (registry.py) reads that as failed.
"""

from __future__ import annotations

import datetime as dt
import json
import logging
import os
import socket
import time
from pathlib import Path

from stable_baselines3.common.callbacks import BaseCallback

from parallel_eplus import io
from parallel_eplus.engine.pipes.leftovers import start_time
from parallel_eplus.runs.run_files import STATUS_FILE, read_status

log = logging.getLogger(__name__)

TRIAL_VARIABLE = "PARALLEL_EPLUS_TRIAL"  # set by whatever runs this training as a Ray Tune trial
EVERY_S = 10.0


def now_iso() -> str:
    return dt.datetime.now().astimezone().isoformat(timespec="seconds")


class RunStatus(BaseCallback):
    """The run's status.json: a context manager around the whole run (how it ended) and a callback while it
    learns (steps done, at most every `every_s` seconds: a write is an fsync)."""

    def __init__(self, run_dir: Path, planned: int, every_s: float = EVERY_S):
        super().__init__()
        self.path = Path(run_dir) / STATUS_FILE
        earlier = read_status(run_dir) or {}  # a resumed run: its sessions' wall time and first start add up
        pid = os.getpid()
        self.status = {
            "state": "running",
            "pid": pid,
            "pid_started": start_time(pid),  # clock ticks since boot: tells a recycled pid from ours
            "host": socket.gethostname(),
            "trial": os.environ.get(TRIAL_VARIABLE) or None,
            "started": now_iso(),
            "first_started": earlier.get("first_started") or earlier.get("started") or now_iso(),
            "updated": now_iso(),
            "steps": int(earlier.get("steps", 0)),
            "planned": int(planned),
            "wall_s": 0.0,
            "error": None,
        }
        self._wall0 = float(earlier.get("wall_s", 0.0))
        self._t0 = self._last = time.monotonic()
        self.every_s = every_s

    def write(self, **changes) -> None:
        self.status.update(changes, updated=now_iso(), wall_s=round(self._wall0 + time.monotonic() - self._t0, 1))
        try:
            io.write_text(self.path, json.dumps(self.status, indent=2) + "\n")
        except OSError as e:  # bookkeeping never stops a run
            log.warning("could not write %s: %s", self.path, e)
        self._last = time.monotonic()

    def __enter__(self) -> RunStatus:
        self.write()
        return self

    def __exit__(self, kind, error, tb) -> bool:
        model = getattr(self, "model", None)  # set once learning starts
        steps = self.status["steps"] if model is None else int(model.num_timesteps)
        if kind is None:
            self.write(state="finished", steps=steps)
        elif issubclass(kind, KeyboardInterrupt):  # Ctrl-C, SIGINT, SIGTERM (errors.Interrupts), `runs stop`
            self.write(state="stopped", steps=steps)
        else:
            first = (str(error).strip().splitlines() or [""])[0]
            self.write(state="failed", steps=steps, error=f"{kind.__name__}: {first}".rstrip(": "))
        return False

    def _on_training_start(self) -> None:
        self.write(steps=int(self.num_timesteps))

    def _on_step(self) -> bool:
        if time.monotonic() - self._last >= self.every_s:
            self.write(steps=int(self.num_timesteps))
        return True

    def _on_rollout_end(self) -> None:  # a batch collected (SAC: every vector step, hence the same limit)
        self._on_step()
