"""Feasibility spike (issue 39, part 2): fork a parked, warmed-up EnergyPlus per episode.

A parent process runs EnergyPlus through input processing, sizing and warm-up, and parks at the run period's first
control step (inside the callback, before the first action is applied). For each episode it forks: the child returns
from the callback and runs the period to its end; the parent stays parked for the next fork. Compared with a fresh
API state per episode in a warm process (one that has run an episode before: what engine/warm_process.py does).

Measured per episode: the child's wall time from fork to exit (and to the end of its run), its minor page faults
(copy-on-write) and CPU time from wait4's rusage; the fresh episode's new_state -> end of run -> delete_state. The
observations of every child are compared bit for bit with a fresh run's. Output files: the child redirects every
descriptor the parent holds open in its output directory to a copy in its own directory (the bytes on disk so far,
then the same offset), and chdir()s so that files EnergyPlus opens by a relative path land in its own directory.

    python scripts/spikes-issue39/fork_episode.py --episodes 8 --days 1
"""

from __future__ import annotations

import argparse
import contextlib
import hashlib
import json
import os
import resource
import shutil
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from pyenergyplus.api import EnergyPlusAPI

from parallel_eplus.buildings.building import load_building
from parallel_eplus.buildings.idf_prep import prepare_idf
from parallel_eplus.buildings.model import control_model
from parallel_eplus.buildings.weather import resolve_weather

api = EnergyPlusAPI()
X = api.exchange
MODEL = control_model("temp_fan")
SENSORS = load_building(None).sensors


class Run:
    """Our EnergyPlus side, reduced: hold the initial action, record every zone timestep's sensors in the run
    period. `park` is called at the run period's first control step (fork mode)."""

    def __init__(self, steps: int, park=None):
        self.steps, self.park = steps, park
        self.action = [e.initial for e in MODEL.actions]
        self.sensor_h: list[int] = []
        self.act_h: list[tuple[int, int]] = []
        self.started = False
        self.pending = True
        self.rows: list[list[float]] = []
        self.calls = 0

    def _ready(self, state) -> bool:
        if self.sensor_h:
            return True
        if not X.api_data_fully_ready(state):
            return False
        self.sensor_h = [X.get_variable_handle(state, s.variable, s.key) for s in SENSORS]
        for i, e in enumerate(MODEL.actions):
            for a in e.actuators:
                self.act_h.append((X.get_actuator_handle(state, a.component_type, a.control_type, a.key), i))
        assert min(self.sensor_h) >= 0 and min(h for h, _ in self.act_h) >= 0
        return True

    def apply(self, state) -> None:
        self.calls += 1
        if not self._ready(state):
            return
        if not self.started and not X.warmup_flag(state) and X.kind_of_sim(state) == 3:
            self.started = True
            if self.park is not None:
                self.park(state)  # the parent never returns from here; a child does, and runs the period
        if self.pending:
            self.pending = False
            for h, i in self.act_h:
                X.api.setActuatorValue(state, h, self.action[i])

    def observe(self, state) -> None:
        if not self._ready(state):
            return
        values = [X.api.getVariableValue(state, h) for h in self.sensor_h]
        if not self.started:
            self.pending = True
            return
        self.rows.append([X.api.dayOfYear(state), X.api.hour(state), X.api.zoneTimeStepNum(state), *values])


def run(model: Path, epw: Path, out: Path, steps: int, park=None, cwd: Path | None = None) -> tuple[Run, dict]:
    """One EnergyPlus run in a new state (`park`: fork mode). Timings: new_state, run, delete_state."""
    t0 = time.monotonic()
    state = api.state_manager.new_state()
    api.runtime.set_console_output_status(state, False)
    r = Run(steps, park)
    api.runtime.callback_after_predictor_after_hvac_managers(state, r.apply)
    api.runtime.callback_end_zone_timestep_after_zone_reporting(state, r.observe)
    t1 = time.monotonic()
    d = str(out) if cwd is None else os.path.relpath(out, cwd)
    status = api.runtime.run_energyplus(state, ["-d", d, "-w", str(epw), str(model)])
    t2 = time.monotonic()
    if FORKED.get("child") is not None:  # a child: report and leave at once (no delete_state: exit frees it)
        child_report(r, status, t2)
    api.state_manager.delete_state(state)
    t3 = time.monotonic()
    assert status == 0, status
    return r, {"new_state_s": t1 - t0, "run_s": t2 - t1, "delete_s": t3 - t2, "total_s": t3 - t0}


FORKED: dict = {}


def open_files() -> list[str]:
    out = []
    for n in os.listdir("/proc/self/fd"):
        with contextlib.suppress(OSError):
            out.append(os.readlink(f"/proc/self/fd/{n}"))
    return out


def redirect_outputs(parent_out: Path, child_out: Path) -> list[str]:
    """In the child: give every descriptor open on a regular file an open file description of its own (after fork
    parent and child share one, offset included). Files in the parent's output directory are copied into the
    child's own (the bytes on disk so far) and written there at the same offset; inputs (the weather file, which
    EnergyPlus reads day by day as the run goes) are reopened read-only at the same offset. Returns what moved."""
    import fcntl
    import stat

    child_out.mkdir(parents=True, exist_ok=True)
    moved = []
    for name in os.listdir("/proc/self/fd"):
        fd = int(name)
        try:
            target = Path(os.readlink(f"/proc/self/fd/{fd}"))
            if not stat.S_ISREG(os.fstat(fd).st_mode):
                continue
        except OSError:
            continue
        flags = fcntl.fcntl(fd, fcntl.F_GETFL)
        offset = os.lseek(fd, 0, os.SEEK_CUR)
        if target.parent == parent_out:
            copy = child_out / target.name
            shutil.copyfile(target, copy)
            new = os.open(copy, os.O_WRONLY | (flags & os.O_APPEND))
            moved.append(target.name)
        elif flags & os.O_ACCMODE == os.O_RDONLY:
            new = os.open(target, os.O_RDONLY)
            moved.append(f"{target.name} (input, reopened)")
        else:
            moved.append(f"{target} (left shared!)")
            continue
        os.lseek(new, offset, os.SEEK_SET)
        os.dup2(new, fd)
        os.close(new)
    return moved


def child_report(r: Run, status: int, t_end: float) -> None:
    k, w, t_fork, moved = FORKED["child"]
    rows = np.array(r.rows)
    ru = resource.getrusage(resource.RUSAGE_SELF)
    msg = {"k": k, "status": status, "to_end_s": t_end - t_fork, "steps": len(rows), "moved": moved,
           "digest": hashlib.sha256(rows.tobytes()).hexdigest(), "minflt_self": ru.ru_minflt,
           "threads": len(os.listdir("/proc/self/task"))}  # fmt: skip
    os.write(w, json.dumps(msg).encode())
    np.save(Path(FORKED["dir"]) / f"rows{k}.npy", rows)
    os._exit(0)


def fork_mode(model: Path, epw: Path, work: Path, steps: int, episodes: int) -> dict:
    parent_out = work / "parent"
    parent_out.mkdir(parents=True)
    results: list[dict] = []
    t_start = time.monotonic()
    info: dict = {}

    def park(state) -> None:
        info["parked_after_s"] = time.monotonic() - t_start
        info["threads_at_park"] = len(os.listdir("/proc/self/task"))
        info["open_in_parent_out"] = sorted(Path(t).name for t in open_files() if t.startswith(str(parent_out)))
        before = set(os.listdir(parent_out))
        for k in range(episodes):
            rd, wr = os.pipe()
            t_fork = time.monotonic()
            pid = os.fork()
            if pid == 0:
                os.close(rd)
                child_dir = work / f"child{k}"
                moved = redirect_outputs(parent_out, child_dir / "parent")
                os.chdir(child_dir)  # relative paths EnergyPlus opens later land in child{k}/parent
                FORKED["child"] = (k, wr, t_fork, moved)
                FORKED["dir"] = str(work)
                return  # the child runs the period from here
            os.close(wr)
            _, status, ru = os.wait4(pid, 0)
            t_exit = time.monotonic()
            data = b""
            while chunk := os.read(rd, 65536):
                data += chunk
            os.close(rd)
            msg = json.loads(data) if data else {"k": k, "status": status}
            msg.update(wall_s=t_exit - t_fork, minflt=ru.ru_minflt, cpu_s=ru.ru_utime + ru.ru_stime, exit=status)
            results.append(msg)
        info["new_files_in_parent_out"] = sorted(set(os.listdir(parent_out)) - before)
        os.write(1, (json.dumps({"fork": results, **info}) + "\n").encode())
        os._exit(0)  # the parent never returns to EnergyPlus: nothing of its buffers reaches the shared files

    os.chdir(work)
    run(model, epw, parent_out, steps, park, cwd=work)
    raise AssertionError("the parent returned from the run")


def fresh_mode(model: Path, epw: Path, work: Path, steps: int, episodes: int) -> dict:
    out = []
    digests = []
    for k in range(episodes + 1):  # the first in a fresh address space, left out (warm_process.py's case)
        r, t = run(model, epw, work / f"fresh{k}", steps)
        rows = np.array(r.rows)
        np.save(work / f"fresh_rows{k}.npy", rows)
        digests.append(hashlib.sha256(rows.tobytes()).hexdigest())
        t["minflt_total"] = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
        out.append(t)
    return {"fresh": out, "digests": digests}


def main() -> None:
    p = argparse.ArgumentParser()
    p.add_argument("--episodes", type=int, default=8)
    p.add_argument("--days", type=int, default=1)
    p.add_argument("--mode", choices=["fork", "fresh", "both"], default="both")
    p.add_argument("--work", type=Path)
    args = p.parse_args()
    if args.mode == "both":
        import subprocess

        work = Path(tempfile.mkdtemp(prefix="fork-spike-"))
        rep = {}
        for mode in ("fresh", "fork", "fresh", "fork"):  # interleaved, each in its own process
            wd = work / f"{mode}{len([k for k in rep if k.startswith(mode)])}"
            wd.mkdir()
            cmd = [sys.executable, __file__, "--mode", mode, "--work", str(wd), "--episodes", str(args.episodes),
                   "--days", str(args.days)]  # fmt: skip
            done = subprocess.run(cmd, capture_output=True, text=True)
            line = [ln for ln in done.stdout.splitlines() if ln.startswith("{")]
            if not line:
                sys.exit(f"{mode} failed: {done.stderr[-3000:]}")
            rep[wd.name] = json.loads(line[-1])
            rep[wd.name]["dir"] = str(wd)
        summarize(rep)
        (work / "report.json").write_text(json.dumps(rep, indent=1))
        print("work:", work)
        return
    work = args.work
    model, epw = work / "model.idf", resolve_weather("CA")
    prepare_idf(MODEL.idf, model, args.days, energyplus_csv=False)
    steps = 96 * args.days
    if args.mode == "fresh":
        print(json.dumps(fresh_mode(model, epw, work, steps, args.episodes)))
    else:
        fork_mode(model, epw, work, steps, args.episodes)


def summarize(rep: dict) -> None:
    med = statistics.median

    def ms(xs) -> str:
        xs = list(xs)
        return f"{med(xs) * 1e3:.0f} ms [{min(xs) * 1e3:.0f}-{max(xs) * 1e3:.0f}]"

    fresh_digests = set()
    for name, r in rep.items():
        if "fresh" in r:
            warm = r["fresh"][1:]
            fresh_digests |= set(r["digests"])
            print(f"{name}: fresh state in a warm process, {len(warm)} episodes: new_state+run+delete "
                  f"{ms(x['total_s'] for x in warm)}; new_state {ms(x['new_state_s'] for x in warm)}, "
                  f"run {ms(x['run_s'] for x in warm)}, delete {ms(x['delete_s'] for x in warm)}; "
                  f"first (fresh address space) {r['fresh'][0]['total_s'] * 1e3:.0f} ms")  # fmt: skip
    for name, r in rep.items():
        if "fork" in r:
            f = r["fork"]
            faults = med(x["minflt"] for x in f)
            print(f"{name}: parked after {r['parked_after_s'] * 1e3:.0f} ms (threads {r['threads_at_park']}); "
                  f"{len(f)} forked episodes: fork->exit {ms(x['wall_s'] for x in f)}, fork->end of run "
                  f"{ms(x['to_end_s'] for x in f)}, cpu {ms(x['cpu_s'] for x in f)}, "
                  f"minor faults {faults:.0f} (~{faults * 4 / 1024:.0f} MiB)")  # fmt: skip
            same = all(x.get("digest") in fresh_digests for x in f)
            print(f"   observations equal to a fresh run's, bit for bit: {same} "
                  f"({len({x.get('digest') for x in f})} distinct among children); steps "
                  f"{[x.get('steps') for x in f][:3]}...; moved {f[0].get('moved')}; open in the parent's "
                  f"output dir at park: {r['open_in_parent_out']}; new there after the children: "
                  f"{r['new_files_in_parent_out']}")  # fmt: skip


if __name__ == "__main__":
    main()
