"""Handing EnergyPlus's callbacks to the C bridge (native.py, eplus_callback.c), and taking back what it did.

The Python `Bridge` answers every callback until the run period's first exchange: then it arms the C callbacks
with its state, and every later step stays in C. Sizing and warm-up are held in C too (`bridge_hold`), without
~2,700 Python callbacks an episode; after the run, `collect` reads the step count, completion and any error back.
"""

from __future__ import annotations

import ctypes
import sys

import numpy as np

from parallel_eplus.errors import ProtocolError


def _ints(xs):
    return (ctypes.c_int * len(xs))(*xs)


def _doubles(xs):
    return (ctypes.c_double * len(xs))(*xs)


class NativeHandoff:
    """The C side of a `Bridge` (a mixin: it reads and sets the Bridge's handles, action and step)."""

    def _hold(self) -> None:
        """Sizing and warm-up in C (`bridge_hold`): what `_apply_action` and `_observe` do there (write the held
        action once per zone timestep, keep the latest sensors) without ~2,700 Python callbacks an episode."""
        if self.native is None or self.python_only or self._holding:
            return
        handles = [h for h, _ in self.actuator_handles]
        indices = [i for _, i in self.actuator_handles]
        status = self.native.bridge_hold(
            len(self.sensor_handles), _ints(self.sensor_handles), len(handles), _ints(handles), _ints(indices),
            len(self.action), _doubles(self.action), int(self.pending), _doubles(self.last_obs),
        )  # fmt: skip
        self._holding = status == 0  # else (too many values for it) Python holds it, as before

    def _unhold(self) -> None:
        last = (ctypes.c_double * len(self.sensors))()
        self.pending = bool(self.native.bridge_unhold(last))
        self.last_obs = list(last)
        self._holding = False

    def _arm(self) -> None:
        """Hand every later step to the C callbacks, in the state this Bridge has reached."""
        if self._actions is not None and self._actions.buf:
            raise ProtocolError("bytes beyond the action frame")
        handles = [h for h, _ in self.actuator_handles]
        indices = [i for _, i in self.actuator_handles]
        replay = self.replay if self.replay is not None else np.zeros((0, len(self.action)))
        status = self.native.bridge_arm(
            -1 if self.raw else self.obs_fd, -1 if self.raw else self.act_fd,
            len(self.sensor_handles), _ints(self.sensor_handles), len(handles), _ints(handles), _ints(indices),
            len(self.action), _doubles(self.action), int(self.pending),
            self.step, self.steps, self.minutes, self.spin_s,
            replay.ctypes.data_as(ctypes.POINTER(ctypes.c_double)), len(replay), self.replayed,
        )  # fmt: skip
        if status != 0:
            raise RuntimeError("the C bridge refused to arm: too many or unmapped sensors or actuators, or a bad pipe")
        self.native, self._armed = None, self.native

    def collect(self) -> None:
        """After the run: take the step count, completion and any error from the C side if it was armed."""
        lib = self._armed
        if lib is None:
            return
        self.step, self.done, self.done_at = lib.bridge_step(), bool(lib.bridge_done()), lib.bridge_done_at()
        self.counters = {
            "waited_s": lib.bridge_wait_s(), "ahead_s": lib.bridge_ahead_s(), "exchanges": lib.bridge_exchanges(),
            "apply_calls": lib.bridge_apply_calls(), "observe_calls": lib.bridge_observe_calls(),
        }  # fmt: skip
        message = lib.bridge_error()
        if message and self.error is None:
            self.error = RuntimeError(message.decode())
            print(f"C bridge: {message.decode()}", file=sys.stderr)
