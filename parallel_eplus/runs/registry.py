"""The run registry behind `parallel-eplus runs`: every run under a folder, what state it is in and how far it got.

It only reads what runs write, each file whole (io.py writes them atomically): status.json (run_status.py),
config.json, checkpoints/, model.zip and episodes.csv. A run from before status.json is listed too, its state
inferred from its files (model.zip: finished, else stopped). A status that says "running" is checked against
the process it names (pid and start time): one killed outright (SIGKILL, out of memory) shows as failed.
"""

from __future__ import annotations

import contextlib
import json
import logging
import os
import signal
import socket
import time
from dataclasses import dataclass, field
from datetime import datetime
from pathlib import Path

import pandas as pd

from parallel_eplus.engine.pipes import leftovers
from parallel_eplus.runs.run_files import (
    MODEL_FILE,
    TARGET_FILE,
    latest_evaluation,
    read_json,
    read_status,
    saved_steps,
    saves_newest_first,
)

log = logging.getLogger(__name__)

CONFIG_FILE = "config.json"
EPISODES_FILE = "episodes.csv"
STALE_S = 900  # a run on another host (not checkable here) silent this long is taken as failed


@dataclass
class RunInfo:
    """One run as the registry sees it."""

    name: str
    path: Path
    state: str  # running, finished, stopped or failed
    process: str  # "pid@host" (and the Ray Tune trial) that runs or ran it; "" for a run without status.json
    steps: int
    planned: int | None
    episodes: int
    wall_s: float | None
    checkpoint: Path | None  # the newest save (checkpoint or model.zip)
    latest: dict[str, dict] = field(default_factory=dict)  # weather -> its latest episode's row of episodes.csv
    note: str = ""  # why the state is what it is, where it was inferred or recorded
    status: dict | None = None
    evaluation: dict | None = None  # the newest evaluation's means (evaluations.csv; `train --eval-every`)
    target: dict | None = None  # when it first met its --target (target.json)


def find_runs(folder: Path) -> list[Path]:
    """Run folders (holding a config.json) in `folder` and one level further down (a sweep's trials)."""
    folder = Path(folder)
    if (folder / CONFIG_FILE).is_file():
        return [folder]
    runs = []
    for child in sorted(p for p in folder.iterdir() if p.is_dir()) if folder.is_dir() else []:
        if (child / CONFIG_FILE).is_file():
            runs.append(child)
        else:
            runs += sorted(p for p in child.iterdir() if p.is_dir() and (p / CONFIG_FILE).is_file())
    return runs


def resolve_run(name: str | Path, folder: Path) -> Path:
    """A run folder from its name under `folder` (as `runs` lists it) or its path."""
    for path in (Path(folder) / name, Path(name)):
        if (path / CONFIG_FILE).is_file():
            return path
    known = ", ".join(p.relative_to(folder).as_posix() for p in find_runs(folder)) if Path(folder).is_dir() else ""
    raise FileNotFoundError(f"no run {str(name)!r} in {folder}" + (f" (runs there: {known})" if known else ""))


def process_alive(status: dict) -> bool | None:
    """Whether the process a status names still runs it: None when it runs on another host (not checkable here)."""
    if status.get("host") != socket.gethostname():
        return None
    pid = int(status.get("pid", 0))
    try:  # /proc/PID/stat: the state is field 3, the start time field 22 (leftovers.start_time)
        fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split() if pid > 0 else []
    except OSError:
        return False
    if not fields or fields[0] in "ZXx":  # gone, or exited and not yet reaped by its parent (a zombie)
        return False
    return status.get("pid_started") in (None, fields[19])


def _process(status: dict) -> str:
    where = f"{status.get('pid')}@{status.get('host')}"
    return f"trial {status['trial']} ({where})" if status.get("trial") else where


def _age_s(stamp: str | None) -> float | None:
    try:
        return time.time() - datetime.fromisoformat(stamp).timestamp()
    except (TypeError, ValueError):
        return None


def _state(run_dir: Path, status: dict | None) -> tuple[str, str, str]:
    """(state, process, note)."""
    if status is None:
        state = "finished" if (run_dir / MODEL_FILE).is_file() else "stopped"
        return state, "", "no status.json (a run from an earlier version): state inferred from its files"
    process, state = _process(status), status["state"]
    if state != "running":  # ended: only a trial's name still says something in a list
        return state, f"trial {status['trial']}" if status.get("trial") else "", status.get("error") or ""
    alive = process_alive(status)
    if alive:
        return "running", process, ""
    if alive is False:
        return "failed", f"{process} gone", "its trainer ended without recording how: killed (SIGKILL, out of memory?)"
    age = _age_s(status.get("updated"))
    if age is not None and age > STALE_S:
        return "failed", f"{process} silent", f"no update for {age / 60:.0f} min from another host"
    return "running", process, "on another host: its process is not checked from here"


def _episodes(run_dir: Path) -> tuple[int, int, dict[str, dict]]:
    """(episodes finished, steps at the last one, weather -> its latest episode's row)."""
    try:
        df = pd.read_csv(run_dir / EPISODES_FILE)
    except (OSError, ValueError):
        return 0, 0, {}
    if df.empty or "weather" not in df:
        return len(df), 0, {}
    counts = df["weather"].value_counts()
    last = df.groupby("weather").tail(1).set_index("weather")
    latest = {str(w): {**row.to_dict(), "count": int(counts[w])} for w, row in last.sort_index().iterrows()}
    return len(df), int(df["timesteps"].iloc[-1]) if "timesteps" in df else 0, latest


def read_run(run_dir: Path, folder: Path | None = None) -> RunInfo:
    """Everything `runs` shows about one run folder."""
    run_dir = Path(run_dir)
    status = read_status(run_dir)
    state, process, note = _state(run_dir, status)
    saves = saves_newest_first(run_dir)
    episodes, episode_steps, latest = _episodes(run_dir)
    steps = max(int((status or {}).get("steps", 0)), episode_steps, saved_steps(saves[0]) if saves else 0)
    try:
        planned = int(json.loads((run_dir / CONFIG_FILE).read_text())["timesteps"])
    except (OSError, ValueError, KeyError):
        planned = None
    planned = int(status["planned"]) if status and status.get("planned") else planned
    wall: float | None = None
    if status is not None:
        wall = float(status.get("wall_s", 0.0))
        if state == "running":  # as of now, not as of its last update
            wall += max(_age_s(status.get("updated")) or 0.0, 0.0)
    name = run_dir.relative_to(folder).as_posix() if folder and run_dir != Path(folder) else run_dir.name
    return RunInfo(name, run_dir, state, process, steps, planned, episodes, wall, saves[0] if saves else None,
                   latest, note, status, latest_evaluation(run_dir), read_json(run_dir / TARGET_FILE))  # fmt: skip


def list_runs(folder: Path) -> list[RunInfo]:
    return [read_run(p, folder) for p in find_runs(folder)]


def stop_run(info: RunInfo, timeout_s: float = 300.0) -> tuple[RunInfo, list[str]]:
    """Stop a running training as Ctrl-C does (SIGINT: it saves a checkpoint and stops every EnergyPlus process),
    wait for it to exit, and return the run as it ended with whatever of its processes or pipes is left. A sweep's
    trial stops alone the same way (experiments/tune_trial.py), and its process ends with it."""
    status = info.status or {}
    if info.state != "running":
        raise ValueError(f"run {info.name} is not running ({info.state})")
    if process_alive(status) is None:
        raise ValueError(f"run {info.name} runs on {status.get('host')}: stop it there (parallel-eplus runs stop)")
    pid = int(status["pid"])
    os.kill(pid, signal.SIGINT)
    deadline = time.monotonic() + timeout_s
    while process_alive(status):
        if time.monotonic() > deadline:
            raise TimeoutError(f"run {info.name} (pid {pid}) did not stop within {timeout_s:.0f} s")
        time.sleep(0.2)
    return read_run(info.path), _left_behind(pid, info.path)


def _energyplus_of(run_dir: Path) -> list[int]:
    """EnergyPlus processes (ours: the callback module) writing into `run_dir`, whichever process started them
    (the trainer itself, or a Ray actor on this host)."""
    inside = str(run_dir.resolve()) + "/"
    found = []
    for proc in Path("/proc").iterdir():
        if proc.name.isdigit():
            with contextlib.suppress(OSError):
                args = (proc / "cmdline").read_bytes().decode(errors="replace").split("\0")
                if leftovers.CALLBACK_MODULE in args and any(a.startswith(inside) for a in args):
                    found.append(int(proc.name))
    return found


def _left_behind(pid: int, run_dir: Path, wait_s: float = 10.0) -> list[str]:
    """The run's EnergyPlus processes and the trainer's pipe directories still there (after `wait_s` of grace)."""
    prefix = f"{leftovers.PREFIX}{pid}-"
    deadline = time.monotonic() + wait_s
    while True:
        left = [f"EnergyPlus process {p}" for p in _energyplus_of(run_dir)]
        left += [f"pipe directory {d}" for d in leftovers.pipe_dirs() if d.name.startswith(prefix)]
        if not left or time.monotonic() > deadline:
            return left
        time.sleep(0.5)
