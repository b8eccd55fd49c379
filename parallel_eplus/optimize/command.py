"""Each step a user could run is run as that command: `python -m parallel_eplus.cli ...` in a child process, its output
appended to a log in the building's folder, a progress bar drawn from what it writes, stopped with SIGINT at a
deadline (a trainer checkpoints then), and stopped the same way when optimize itself is interrupted."""

from __future__ import annotations

import logging
import shlex
import signal
import subprocess
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from tqdm import tqdm

from parallel_eplus.optimize.folders import now_iso

log = logging.getLogger(__name__)

POLL_S = 2.0
STOP_WAIT_S = 900.0  # a trainer saving its checkpoint and stopping its EnergyPlus workers after SIGINT


def cli(*args: str) -> list[str]:
    return [sys.executable, "-m", "parallel_eplus.cli", *args]


@dataclass(frozen=True)
class Outcome:
    returncode: int
    stopped: bool  # stopped at its deadline (SIGINT)
    log: Path
    seconds: float


def run_command(args: list[str], log_path: Path, cwd: Path, desc: str, *,
                deadline: float | Callable[[], float] | None = None,
                progress: Callable[[], tuple] | None = None, show: bool = True,
                bar: tqdm | None = None) -> Outcome:  # fmt: skip
    """Run `parallel-eplus ARGS` in `cwd`, its output appended to `log_path`. `progress`: () -> (done, total) or (done,
    total, note) for the bar, polled every POLL_S seconds. At `deadline` (time.time(), or a callable asked at each
    poll) the child gets SIGINT and is waited for. The child has its own session, so a Ctrl-C at the terminal reaches
    this process only, which passes exactly one SIGINT on (a second one could cut a checkpoint short), waits for the
    child, then raises KeyboardInterrupt. `bar`: a stage's bar spanning several commands (else one of its own)."""
    log_path.parent.mkdir(parents=True, exist_ok=True)
    t0 = time.time()
    with open(log_path, "a") as out:
        out.write(f"\n=== {now_iso()} $ parallel-eplus {shlex.join(args)}\n")
        out.flush()
        proc = subprocess.Popen(cli(*args), cwd=cwd, stdout=out, stderr=subprocess.STDOUT, start_new_session=True)
        own_bar = bar is None
        bar = bar if bar is not None else stage_bar(desc, show)
        stopped = False
        try:
            while True:
                try:
                    proc.wait(timeout=POLL_S)
                    break
                except subprocess.TimeoutExpired:
                    pass
                _advance(bar, progress)
                limit = deadline() if callable(deadline) else deadline
                if limit is not None and not stopped and time.time() >= limit:
                    log.info("%s: its share of the budget is spent; stopping it (SIGINT: it keeps a checkpoint)", desc)
                    proc.send_signal(signal.SIGINT)
                    stopped = True
            _advance(bar, progress)
        except KeyboardInterrupt:
            if not stopped:
                proc.send_signal(signal.SIGINT)
            _wait_for(proc, desc)
            raise
        finally:
            if own_bar:
                bar.close()
    return Outcome(proc.returncode, stopped, log_path, time.time() - t0)


def stage_bar(desc: str, show: bool, total: int | None = None, unit: str = "") -> tqdm:
    return tqdm(desc=desc, total=total, unit=unit, disable=not show, leave=True, dynamic_ncols=True)


def _advance(bar: tqdm, progress: Callable[[], tuple] | None) -> None:
    if progress is None:
        bar.refresh()
        return
    try:
        done, total, *note = progress()
    except (OSError, ValueError):
        return
    if note:
        bar.set_postfix_str(note[0], refresh=False)
    if total and bar.total != total:
        bar.total = total
    bar.n = min(done, total) if total else done
    bar.refresh()


def _wait_for(proc: subprocess.Popen, desc: str) -> None:
    """After an interrupt: the child finishes its own cleanup; further Ctrl-Cs are ignored, and only after
    STOP_WAIT_S is it terminated."""
    log.warning("interrupted: waiting for %s to stop (it keeps what it finished)", desc)
    end = time.time() + STOP_WAIT_S
    while time.time() < end:
        try:
            proc.wait(timeout=max(1.0, end - time.time()))
            return
        except subprocess.TimeoutExpired:
            break
        except KeyboardInterrupt:
            log.warning("still waiting for %s to save what it has", desc)
    proc.terminate()
    proc.wait(timeout=60)


def failure(log_path: Path) -> str:
    """Why a command failed, from its log's last session: its ERROR lines (with their indented details), else its
    last line."""
    try:
        text = log_path.read_text(errors="replace").rsplit("\n=== ", 1)[-1]
    except OSError:
        return f"no log at {log_path}"
    lines = [ln for ln in text.splitlines()[1:] if ln.strip()]
    errors, detail = [], False
    for ln in lines:
        if " ERROR " in ln:
            errors.append(ln.split(" ERROR ", 1)[1].split(": ", 1)[-1])
            detail = True
        elif detail and ln.startswith("  "):
            errors.append(ln.strip())
        else:
            detail = False
    picked = errors[-4:] or [ln for ln in lines if "Error" in ln][-1:] or lines[-1:]
    return " ".join(picked)[:600] or "no output"
