"""Spike (issue 39, part 2b): fork per episode through our real EnergyPlus side (engine/bridge.py, the C bridge)
and our pipes, ten consecutive 1-day episodes, against EnergyPlus alone and today's env (prepared episodes).

EnergyPlus side (`serve`): one process runs input processing, sizing and warm-up (the C bridge holding the initial
action) and parks inside the callback at the run period's first control step, before observation 0 is written.
For each request line on stdin (episode dir, pipes, log) it forks; the child gives every regular-file descriptor an
open file description of its own (outputs copied into the episode's directory and written at the same offset,
inputs such as the weather file reopened at the same offset), chdir()s into the episode's directory (the parent ran
with a relative `-d .`, so files EnergyPlus opens later land there), points fds 1 and 2 at the episode's log, opens
the episode's FIFOs and returns into EnergyPlus: the Bridge writes observation 0, reads action 1 and arms the C
bridge on the child's descriptors. The parent answers `pid N`, reaps the child and answers `done N CODE`.

Driver (`bench`): our PipePair, the env's frames; rounds interleave alone / fork / env.

    python scripts/spikes-issue39/fork_pipes.py bench --episodes 10 --rounds 3
"""

from __future__ import annotations

import argparse
import contextlib
import fcntl
import json
import os
import shutil
import stat
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

# -- the EnergyPlus side ---------------------------------------------------------------------------


def own_descriptors(template_dir: Path, episode_dir: Path) -> list[str]:
    """After fork: every fd open on a regular file gets its own open file description (see the module doc)."""
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
        if target.parent == template_dir:
            shutil.copyfile(target, episode_dir / target.name)
            new = os.open(episode_dir / target.name, os.O_WRONLY | (flags & os.O_APPEND))
        elif flags & os.O_ACCMODE == os.O_RDONLY:
            new = os.open(target, os.O_RDONLY)
        else:
            raise RuntimeError(f"a file open for writing outside the template's directory: {target}")
        os.lseek(new, offset, os.SEEK_SET)
        os.dup2(new, fd)
        os.close(new)
        moved.append(target.name)
    return moved


def serve(args) -> int:
    from pyenergyplus.api import EnergyPlusAPI

    from parallel_eplus.engine import native, pipe
    from parallel_eplus.engine.bridge import Bridge

    reply = os.dup(1)
    os.dup2(os.open(os.devnull, os.O_WRONLY), 1)
    template = Path(args.template).resolve()
    template.mkdir(parents=True, exist_ok=True)
    os.chdir(template)
    children: dict[int, int] = {}

    def answer(text: str) -> None:
        os.write(reply, (text + "\n").encode())

    class ParkingBridge(Bridge):
        def _apply_action(self, state) -> None:
            if not self.started and self._handles_ready(state) and self._in_run_period(state):
                if self._holding:
                    self._unhold()
                park(self)  # returns in a child only
            super()._apply_action(state)

    def park(bridge) -> None:
        answer("parked")
        for line in sys.stdin.buffer:
            req = json.loads(line)
            for pid in list(children):  # reap the episodes that ended
                done, status = os.waitpid(pid, os.WNOHANG)
                if done:
                    answer(f"done {pid} {os.waitstatus_to_exitcode(status)}")
                    del children[pid]
            pid = os.fork()
            if pid == 0:
                episode = Path(req["dir"])
                own_descriptors(template, episode)
                os.chdir(episode)
                log = os.open(req["log"], os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)
                os.dup2(log, 1)
                os.dup2(log, 2)
                os.close(log)
                obs_fd = os.open(req["obs"], os.O_WRONLY | os.O_NONBLOCK)
                os.set_blocking(obs_fd, True)
                act_fd = os.open(req["act"], os.O_RDONLY | os.O_NONBLOCK)
                bridge.obs_fd, bridge.act_fd, bridge.raw = obs_fd, act_fd, False
                bridge._wait, bridge._actions = pipe.wait_readable(act_fd), pipe.FrameReader(act_fd)
                CHILD["in"] = True
                return
            children[pid] = 1
            answer(f"pid {pid}")
        for pid in children:  # stdin closed: the owner is gone
            with contextlib.suppress(ChildProcessError):
                os.waitpid(pid, 0)
        os._exit(0)  # never back into EnergyPlus: the parent's buffers stay out of every episode's files

    api = EnergyPlusAPI()
    state = api.state_manager.new_state()
    api.runtime.set_console_output_status(state, False)
    bridge = ParkingBridge(api, None, None, "temp_fan", args.steps, args.initial_action, 0.0)
    for s in bridge.sensors:
        api.exchange.request_variable(state, s.variable, s.key)
    keep = native.register(api, state, bridge, native.bridge_library())
    status = api.runtime.run_energyplus(state, ["-d", ".", "-w", str(Path(args.epw).resolve()), str(args.idf)])
    bridge.collect()
    del keep
    code = 0 if status == 0 and bridge.done and bridge.error is None else 1
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(code)  # the child: no delete_state, the exit frees it


CHILD: dict = {}


# -- the driver --------------------------------------------------------------------------------------


def fork_episodes(days: int, episodes: int, work: Path) -> dict:
    """`episodes` consecutive episodes through one forking EnergyPlus side: wall seconds, start-up included."""
    from parallel_eplus.buildings.idf_prep import prepare_idf
    from parallel_eplus.buildings.model import control_model
    from parallel_eplus.buildings.weather import resolve_weather
    from parallel_eplus.engine import pipe
    from parallel_eplus.envs.env import EnergyPlusEnv

    t0 = time.perf_counter()
    model = control_model("temp_fan")
    env = EnergyPlusEnv(weather="CA", run_days=days, prepare_next=False)  # for the action's scaling only
    scale = env.sim.low, env.sim.high
    env.close()
    idf = work / "model.idf"
    prepare_idf(model.idf, idf, days, energyplus_csv=False)
    steps = 96 * days
    cmd = [sys.executable, __file__, "serve", "--template", str(work / "template"), "--idf", str(idf), "--epw",
           str(resolve_weather("CA")), "--steps", str(steps), "--initial-action",
           *[str(e.initial) for e in model.actions]]  # fmt: skip
    proc = subprocess.Popen(cmd, stdin=subprocess.PIPE, stdout=subprocess.PIPE, start_new_session=True)
    assert proc.stdout.readline().strip() == b"parked"
    pipes = pipe.PipePair()
    action = pipe.encode([(lo + hi) / 2 for lo, hi in zip(*scale, strict=True)])  # action 0 in [-1, 1], scaled
    resets, obs_rows = [], []
    try:
        for k in range(episodes):
            t = time.perf_counter()
            d = work / f"episode-{k}"
            d.mkdir()
            req = {"dir": str(d), "log": str(d / "energyplus.log"), "obs": str(pipes.obs_path),
                   "act": str(pipes.act_path)}  # fmt: skip
            pipes.drain()
            proc.stdin.write(json.dumps(req).encode() + b"\n")
            proc.stdin.flush()
            line = proc.stdout.readline().split()
            while line[0] == b"done":
                line = proc.stdout.readline().split()
            pid = int(line[1])
            pipes.watch(pid, lambda: True)
            code, values = pipes.recv(60, 0.0)
            resets.append(time.perf_counter() - t)
            rows = [values]
            while code != pipe.END:
                pipes.send(action)
                code, values = pipes.recv(60, 0.0)
                rows.append(values)
            obs_rows.append(np.array(rows))
    finally:
        proc.stdin.close()
        proc.wait(timeout=30)
        pipes.close()
    wall = time.perf_counter() - t0
    return {"wall_s": wall, "resets_s": resets, "rows": obs_rows}


def env_rows(days: int, episodes: int, work: Path) -> list[np.ndarray]:
    """The same episodes through today's env (its raw frames are what the Observer gets: compare the sensors)."""
    from parallel_eplus.envs.env import EnergyPlusEnv

    env = EnergyPlusEnv(weather="CA", run_days=days, output_dir=work, energyplus_csv=False)
    out = []
    try:
        for _ in range(episodes):
            _, info = env.reset()
            rows, terminated = [env.sim._sensed], False
            while not terminated:
                _, _, terminated, _, info = env.step(np.zeros(env.action_space.shape, np.float32))
                rows.append(env.sim._sensed)
            out.append(np.array(rows))
    finally:
        env.close()
    return out


def bench(args) -> int:
    from parallel_eplus.bench.short import alone_episodes, env_episodes

    rows = []
    with tempfile.TemporaryDirectory(prefix="fork-pipes-") as tmp:
        for r in range(args.rounds):
            alone = alone_episodes(args.days, args.episodes, "CA", Path(tmp) / f"alone{r}")
            (Path(tmp) / f"fork{r}").mkdir()
            fork = fork_episodes(args.days, args.episodes, Path(tmp) / f"fork{r}")
            env = env_episodes(args.days, args.episodes, "CA", True, Path(tmp) / f"env{r}")
            rows.append((alone["wall_s"], fork["wall_s"], env["wall_s"]))
            print(f"round {r}: alone {alone['wall_s']:.2f} s, fork {fork['wall_s']:.2f} s, env (prepared) "
                  f"{env['wall_s']:.2f} s; fork resets p50 {statistics.median(fork['resets_s'][1:]) * 1e3:.1f} ms; "
                  f"alone's runs {' '.join(f'{x * 1e3:.0f}' for x in alone['runs_s'])} ms", flush=True)  # fmt: skip
        ref = env_rows(args.days, 2, Path(tmp) / "ref")
        same = all(np.array_equal(ref[0], f[:, 4:]) for f in fork["rows"])
        print(f"fork episodes' sensors equal today's env's, bit for bit: {same} ({len(fork['rows'])} episodes, "
              f"{len(fork['rows'][0])} frames each)")  # fmt: skip
        files = sorted(p.name for p in (Path(tmp) / f"fork{args.rounds - 1}" / "episode-3").iterdir())
        print("an episode's directory:", files, "; the template's:",
              sorted(p.name for p in (Path(tmp) / f"fork{args.rounds - 1}" / "template").iterdir()))  # fmt: skip
    med = statistics.median
    print(
        f"medians of per-round ratios: fork/alone {med(f / a for a, f, _ in rows):.3f}, "
        f"env/alone {med(e / a for a, _, e in rows):.3f}, fork/env {med(f / e for _, f, e in rows):.3f}"
    )
    return 0


def main() -> int:
    p = argparse.ArgumentParser()
    sub = p.add_subparsers(dest="cmd", required=True)
    s = sub.add_parser("serve")
    s.add_argument("--template", required=True)
    s.add_argument("--idf", required=True)
    s.add_argument("--epw", required=True)
    s.add_argument("--steps", type=int, required=True)
    s.add_argument("--initial-action", type=float, nargs="*", default=[])
    b = sub.add_parser("bench")
    b.add_argument("--days", type=int, default=1)
    b.add_argument("--episodes", type=int, default=10)
    b.add_argument("--rounds", type=int, default=3)
    args = p.parse_args()
    return serve(args) if args.cmd == "serve" else bench(args)


if __name__ == "__main__":
    sys.exit(main())
