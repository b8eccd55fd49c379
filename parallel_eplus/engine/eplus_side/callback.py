"""The EnergyPlus process: runs one simulation through the pyenergyplus API, its steps in engine/eplus_side/bridge.py.

    python -m parallel_eplus.engine.eplus_side.callback --act-pipe A --obs-pipe O --idf M.idf --epw W.epw \
        --output-dir D --model temp_fan --steps N --initial-action 20 20 4 4

Without pipes it runs EnergyPlus alone for benchmarks (bench/raw.py): `--replay A.npy` applies one action
row per step where the env's actions would land, stops after `--steps`, and prints the stepping time.
With `--native LIB` (native.py) every step after the first runs in C (eplus_callback.c). With `--serve` it runs
episode after episode, each request a `main` (warm_process.py); with `--template` it parks at the run period's
first control step and forks an episode per request (fork_side.py).
"""

from __future__ import annotations

import argparse
import contextlib
import os
import sys
import traceback
from collections.abc import Callable
from pathlib import Path

import numpy as np

from parallel_eplus.engine.eplus_side import native
from parallel_eplus.engine.eplus_side.bridge import Bridge
from parallel_eplus.engine.pipes import frames


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    p = argparse.ArgumentParser(description="Run one EnergyPlus simulation driven over named pipes.")
    p.add_argument("--act-pipe", help="omit both pipes to run EnergyPlus alone (raw, for benchmarks)")
    p.add_argument("--obs-pipe")
    p.add_argument("--idf", required=True)
    p.add_argument("--epw", required=True)
    p.add_argument("--output-dir", required=True)
    p.add_argument("--model", default="temp_fan")
    p.add_argument("--building", help="a building spec (TOML); its sensors and actions replace --model's")
    p.add_argument("--steps", type=int, required=True, help="zone timesteps in the run period")
    p.add_argument("--initial-action", type=float, nargs="*", default=[])
    p.add_argument("--builtin-residual", action="store_true",
                   help="actions correct the building's own setpoint schedules (bridge.py)")  # fmt: skip
    p.add_argument("--relinquish", action="store_true",
                   help="a NaN action value releases its actuators to the model's own control")  # fmt: skip
    p.add_argument("--spin-us", type=float, default=0.0, help="poll this long for an action before blocking")
    p.add_argument("--native", help="the compiled C bridge (native.py) to run each step in; default: Python")
    p.add_argument("--replay", help="without pipes: a .npy of one action row per step (physical units) to apply")
    p.add_argument("--branching", action="store_true",
                   help="serve forks of the episode where it awaits an action (branch.py: the oracle)")  # fmt: skip
    return p.parse_args(argv)


def main(argv: list[str] | None = None) -> int:
    """One episode. A process that runs many (warm_process.py) gets back everything it opened: fds, the state."""
    args = parse_args(argv)
    opened: list[int] = []
    try:
        return _run(args, opened)
    finally:
        for fd in opened:
            with contextlib.suppress(OSError):
                os.close(fd)


def _run(args: argparse.Namespace, opened: list[int]) -> int:
    # Open our ends first. The env holds both FIFOs open, so neither open waits for it; if it died after
    # starting us, there is no reader and a blocking open would wait forever: ENXIO, and we exit.
    obs_fd = act_fd = None
    if args.obs_pipe and args.act_pipe:
        try:
            obs_fd = os.open(args.obs_pipe, os.O_WRONLY | os.O_NONBLOCK)
        except OSError as e:
            print(f"the env is gone before EnergyPlus started ({e}); exiting", file=sys.stderr)
            return 1
        opened.append(obs_fd)
        os.set_blocking(obs_fd, True)
        act_fd = os.open(args.act_pipe, os.O_RDONLY | os.O_NONBLOCK)
        opened.append(act_fd)

    def fail(status: float) -> int:
        return tell_failure(obs_fd, status)

    try:
        from pyenergyplus.api import EnergyPlusAPI

        api = EnergyPlusAPI()
        state = api.state_manager.new_state()
        api.runtime.set_console_output_status(state, False)
        replay = np.load(args.replay) if args.replay else None
        kind = Bridge
        if args.branching:
            from parallel_eplus.engine.eplus_side.branch import BranchingBridge as kind
        bridge = kind(
            api, act_fd, obs_fd, args.model, args.steps, args.initial_action, args.spin_us * 1e-6, replay,
            args.building, args.builtin_residual, args.relinquish,
        )  # fmt: skip
        if args.branching:
            bridge.open_branching(Path(args.act_pipe).parent)
        for s in bridge.sensors:  # EnergyPlus gathers only requested variables: a model need not report them
            if not s.meter:
                api.exchange.request_variable(state, s.variable, s.key)
        keep = native.register(api, state, bridge, args.native)
        status = api.runtime.run_energyplus(state, ["-d", args.output_dir, "-w", args.epw, args.idf])
        bridge.collect()
        api.state_manager.delete_state(state)  # its memory is reused by the next episode's state
        del keep
    except BaseException:  # noqa: BLE001
        traceback.print_exc()
        return fail(-1.0)
    return outcome(bridge, status, fail)


def tell_failure(obs_fd: int | None, status: float) -> int:
    """An ERROR frame to the env (if there is one to tell), and the episode's exit code."""
    if obs_fd is not None:
        with contextlib.suppress(OSError):  # if the env is gone, there is nobody to tell
            os.write(obs_fd, frames.encode([status], frames.ERROR))
    return 1


def outcome(bridge: Bridge, status: int, fail: Callable[[float], int]) -> int:
    """An episode's exit code once EnergyPlus has returned (`fail` tells the env why it failed)."""
    if bridge.error is not None:
        return fail(-2.0)
    if status != 0:
        print(f"EnergyPlus exited with status {status}", file=sys.stderr)
        return fail(float(status))
    if not bridge.done:
        print(f"simulation ended after {bridge.step} of {bridge.steps} steps", file=sys.stderr)
        return fail(-3.0)
    if bridge.raw:  # for benchmarks: the time its steps took, start-up excluded, as the vector env is timed
        print(f"stepping_s {bridge.done_at - bridge.started_at:.6f}")
    if bridge.counters:  # where the stepping time went (docs/speed.md): the C side's waits for actions, its calls
        stepping = bridge.done_at - bridge.started_at
        print(f"bridge stepping_s {stepping:.6f}", *(f"{k} {v}" for k, v in bridge.counters.items()))
    return 0


if __name__ == "__main__":
    if sys.argv[1:2] == ["--serve"]:  # episode after episode in this process (warm_process.py)
        from parallel_eplus.engine.eplus_side.warm import serve

        sys.exit(serve(main))
    if sys.argv[1:2] == ["--template"]:  # parked at the first control step, forked per episode (fork_side.py)
        from parallel_eplus.engine.eplus_side.fork import serve_template

        sys.exit(serve_template(sys.argv[2:], sys.modules[__name__]))
    sys.exit(main())
