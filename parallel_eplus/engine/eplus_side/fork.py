"""The EnergyPlus side of a forked episode (issue 39): one process parked at the run period's first control step,
forked once per episode. Our side is engine/episodes/fork.py.

With both cores stepping, every short episode used to pay EnergyPlus's input processing, sizing and warm-up again
(~0.14 s of a core for the data center; a one-day episode's steps take ~0.01 s). A template pays them once per
model, weather file and run period: it runs EnergyPlus (the C bridge holding the initial action) up to the run
period's first control step and parks there, inside the callback, before observation 0 is written. For each
request line on its stdin it forks; the child is the episode: it gets file descriptions of its own (after `fork`
parent and child share each file's offset: an output open in the template's directory is copied into the episode's
and written there at the same offset, an input such as the weather file, which EnergyPlus reads day by day, is
reopened read-only at its offset), `chdir`s into the episode's directory (the template runs with `-d .`, so what
EnergyPlus opens later by path lands there), points fds 1 and 2 at the episode's log, opens the episode's FIFOs
and returns into EnergyPlus: the Bridge writes observation 0, reads action 1 and arms the C bridge on the child's
descriptors, as in a process of its own. The template never returns into EnergyPlus (its buffers reach no file).

Answers, one line each on its stdout: `parked`; `pid PID` per request; `done PID CODE` when it reaped a child.
Its stdin closing (the env closed it, exited or was killed) kills its children and ends it.

    python -m parallel_eplus.engine.eplus_side.callback --template --pipes DIR --idf M --epw W --output-dir . ...
"""

from __future__ import annotations

import contextlib
import json
import os
import select
import shutil
import signal
import sys
import traceback
from pathlib import Path
from typing import Any

from parallel_eplus.engine.eplus_side import native
from parallel_eplus.engine.eplus_side.bridge import Bridge
from parallel_eplus.engine.eplus_side.descriptors import own_descriptions, reopened_copy
from parallel_eplus.engine.pipes import frames

TEMPLATE_LOG = "energyplus.log"  # the template's own log, in its directory; each child writes its episode's


class ParkingBridge(Bridge):
    """The Bridge, parked (`park`) where the run period's first control step begins, before observation 0."""

    park: Any = None

    def _apply_action(self, state) -> None:
        if not self.started and self.obs_fd is None and self._handles_ready(state) and self._in_run_period(state):
            if self._holding:
                self._unhold()
            self.park(self)  # returns in a child only, its pipes set: the Bridge goes on as a cold episode's
        super()._apply_action(state)


def serve_template(argv: list[str], side: Any) -> int:
    """Run the template (`argv`: eplus_callback's arguments, with `--pipes DIR` for `parallel-eplus clean`);
    `side`: eplus_callback's module (its parse_args, outcome and tell_failure)."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C is the learner's to handle; it closes us
    if "--pipes" in argv:
        i = argv.index("--pipes")
        argv = argv[:i] + argv[i + 2 :]
    args = side.parse_args(argv)
    reply = os.dup(1)  # our answers; fd 1 joins fd 2, the template's log
    os.dup2(2, 1)
    from pyenergyplus.api import EnergyPlusAPI

    api = EnergyPlusAPI()
    state = api.state_manager.new_state()
    api.runtime.set_console_output_status(state, False)
    bridge = ParkingBridge(
        api, None, None, args.model, args.steps, args.initial_action, 0.0, None, args.building, args.builtin_residual,
        args.relinquish,
    )  # fmt: skip
    child: dict = {}
    bridge.park = lambda b: _park(b, reply, Path.cwd(), child)
    for s in bridge.sensors:
        if not s.meter:
            api.exchange.request_variable(state, s.variable, s.key)
    keep = native.register(api, state, bridge, args.native)
    try:
        status = api.runtime.run_energyplus(state, ["-d", args.output_dir, "-w", args.epw, args.idf])
        bridge.collect()
        code = side.outcome(bridge, status, lambda s: side.tell_failure(bridge.obs_fd, s)) if child else 1
    except BaseException:  # noqa: BLE001
        traceback.print_exc()
        code = side.tell_failure(bridge.obs_fd, -1.0) if child else 1
    del keep
    with contextlib.suppress(Exception):
        sys.stdout.flush()
        sys.stderr.flush()
    os._exit(code)  # a child: no delete_state (its exit frees it); a template that never parked: it failed


def _park(bridge: Bridge, reply: int, template_dir: Path, child: dict) -> None:
    """Serve fork requests until stdin closes; return only in a child, set up as its episode."""
    answer = lambda text: os.write(reply, (text + "\n").encode())  # noqa: E731 - one write: a whole line
    children: dict[int, int] = {}  # pidfd -> pid
    answer("parked")
    buf = b""
    while True:
        ready, _, _ = select.select([0, *children], [], [])
        for fd in ready:
            if fd in children:  # a child ended: reap it
                pid = children.pop(fd)
                os.close(fd)
                _, status = os.waitpid(pid, 0)
                answer(f"done {pid} {os.waitstatus_to_exitcode(status)}")
        if 0 not in ready:
            continue
        data = os.read(0, 65536)
        if not data:  # our owner is gone or closed us: so are its episodes
            for fd, pid in children.items():
                with contextlib.suppress(OSError):
                    signal.pidfd_send_signal(fd, signal.SIGKILL)
                with contextlib.suppress(ChildProcessError):
                    os.waitpid(pid, 0)
            os._exit(0)
        buf += data
        while b"\n" in buf:
            line, buf = buf.split(b"\n", 1)
            request = json.loads(line)
            sys.stdout.flush()
            sys.stderr.flush()
            pid = os.fork()
            if pid == 0:
                for fd in children:
                    os.close(fd)
                os.close(reply)
                _become_episode(bridge, request, template_dir)
                child["request"] = request
                return
            children[os.pidfd_open(pid)] = pid
            answer(f"pid {pid}")


def _become_episode(bridge: Bridge, request: dict, template_dir: Path) -> None:
    """In the child: its own files, its directory, its log and its pipes (see the module's docstring)."""
    null = os.open(os.devnull, os.O_RDONLY)
    os.dup2(null, 0)
    os.close(null)
    episode = Path(request["dir"])
    log = os.open(request["log"], os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)
    os.dup2(log, 1)
    os.dup2(log, 2)
    os.close(log)
    try:
        _own_descriptions(template_dir, episode)
        for f in template_dir.iterdir():  # what EnergyPlus wrote and closed before the park (its listings)
            if f.is_file() and not (episode / f.name).exists():
                shutil.copyfile(f, episode / f.name)
        os.chdir(episode)
        obs_fd = os.open(request["obs"], os.O_WRONLY | os.O_NONBLOCK)  # ENXIO: the env is gone
        os.set_blocking(obs_fd, True)
        act_fd = os.open(request["act"], os.O_RDONLY | os.O_NONBLOCK)
    except OSError:
        traceback.print_exc()
        sys.stderr.flush()
        os._exit(1)
    bridge.obs_fd, bridge.act_fd, bridge.raw = obs_fd, act_fd, False
    bridge._wait, bridge._actions = frames.wait_readable(act_fd), frames.FrameReader(act_fd)
    bridge.spin_s = float(request["spin_us"]) * 1e-6


def _own_descriptions(template_dir: Path, episode: Path) -> None:
    """Descriptions of the episode's own (descriptors.py): an output of the template's directory is copied into the
    episode's; an output anywhere else is an error."""

    def output(target: Path, flags: int) -> int:
        if target.parent != template_dir:
            raise OSError(f"a file open for writing outside the template's directory: {target}")
        return reopened_copy(target, episode, flags)

    own_descriptions(output)
