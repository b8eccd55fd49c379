"""EnergyPlus's side of each control step, in Python: read the sensors, send them, apply the answer.

Timing (one control step = one zone timestep, no shift between an observation and its action):
- warmup and sizing hold the initial action and never produce a step;
- at the run period's first apply point, observation 0 (the state at the end of warmup) goes out and
  action 1 comes back and is applied to timestep 1;
- at the end of every zone timestep (after zone reporting) observation k goes out; action k+1 is read
  where it is applied, at timestep k+1's first apply point: what EnergyPlus does in between (the next
  timestep's weather, surfaces) does not depend on it, so the env's turnaround and the pipe crossings
  overlap that work (with the same actuator values at the same points, the trajectories are those of
  reading it at once);
- after timestep N the observation goes out as an END frame and no action is awaited.
The apply point (native.py registers it): AfterPredictorAfterHVACManagers, where node setpoints and fan
flows win over the model's setpoint managers; BeginTimestepBeforePredictor for a building whose actions
are all thermostat setpoints (`Building.before_predictor`), which the zone predictor reads: set after it,
they would act a timestep late. Actuators keep their values, so the action is written once per zone
timestep. Frame values: year, day of year, hour, minute (when the
observation was taken; EnergyPlus's own clock at this point is the last sub-timestep's), then the sensors.

With the C bridge (native.py, eplus_callback.c; the hand-off: native_handoff.py) the callbacks EnergyPlus calls
are C: they hand each call to this Bridge until its first exchange is done, then the Bridge arms them and every
later step stays in C.
"""

from __future__ import annotations

import ctypes
import os
import time
import traceback

import numpy as np

from parallel_eplus.buildings.building import load_building
from parallel_eplus.buildings.datacenter import control_model
from parallel_eplus.engine.eplus_side.handoff import NativeHandoff
from parallel_eplus.engine.pipes import frames
from parallel_eplus.errors import ProtocolError

KIND_RUN_PERIOD_WEATHER = 3  # api.exchange.kind_of_sim during a weather-file run period


class Bridge(NativeHandoff):
    """Holds the handles and the current action; its two methods are the EnergyPlus callbacks."""

    def __init__(
        self,
        api,
        act_fd: int | None,
        obs_fd: int | None,
        model: str,
        steps: int,
        initial: list[float],
        spin_s: float = 0.0,
        replay: np.ndarray | None = None,
        building: str | None = None,
        builtin_residual: bool = False,
        relinquish: bool = False,
    ):
        """With no pipes (`--raw`): EnergyPlus alone, for benchmarks. It holds the initial action all run,
        or with `replay` (steps x actions, physical units) takes each step's action from it instead.

        `builtin_residual`: each action is a correction (physical units) to what the building's own controls set
        each actuator to, its setpoint schedule (`Building.own`), read here at the step it applies to: read on
        the env's side, with the observation, it would be the step before's, a step late at every change.

        `relinquish`: an action value that is NaN releases its actuators (EnergyPlus's own control for them: the
        model's setpoint managers and fan controls), and every value is written at every apply-point call, each HVAC
        system timestep, since the model's setpoint managers write those nodes at each (the BACnet device)."""
        self.api = api
        self.x = api.exchange
        self.act_fd = act_fd
        self.obs_fd = obs_fd
        spec = load_building(building)  # None: the data center, whose variants `model` names
        self.sensors = spec.sensors
        # Meters and scaled values are read here, in Python: the C bridge reads output variables as they are.
        # With `builtin_residual`, each actuator's own schedule is added here too.
        self.relinquish = relinquish
        self.python_only = builtin_residual or relinquish or any(s.meter or s.scale != 1.0 for s in self.sensors)
        self.own = spec.own if builtin_residual else None
        self.node_schedules = spec.node_schedules if building and model != "baseline" else ()
        self.own_sensors: list[int] = []  # per actuator handle: the sensor index of its own schedule
        # relinquish: per actuator handle, the sensor of the schedule a released node gets back (its scheduled
        # manager is gone from the copy: supply.py), -1 where EnergyPlus's own control returns by itself
        self.fallback: list[int] = []
        self.step_s = 900.0  # seconds per zone timestep, to turn a meter's joules into watts
        self.elements = spec.actions if building and model != "baseline" else control_model(model).actions
        self.before_predictor = bool(building) and model != "baseline" and spec.before_predictor  # the apply point
        if len(initial) != len(self.elements):
            raise SystemExit(f"--initial-action needs {len(self.elements)} values, got {len(initial)}")
        self.action = list(initial)
        self.steps = steps
        self.step = 0
        self.started = False
        self.done = False
        self.pending = True  # the current action has not been written to the actuators yet
        self.awaiting = False  # an observation is out and its action not read yet
        self.minutes = 15
        self.error: BaseException | None = None
        self.sensor_handles: list[int] = []
        self.actuator_handles: list[tuple[int, int]] = []  # (handle, action index)
        self.last_obs: list[float] = [0.0] * len(self.sensors)
        self.raw = obs_fd is None
        self._wait = None if act_fd is None else frames.wait_readable(act_fd)
        self._actions = None if act_fd is None else frames.FrameReader(act_fd)
        self.spin_s = spin_s
        self.replay = None if replay is None else np.ascontiguousarray(replay, dtype=np.float64)
        if self.replay is not None and (self.replay.ndim != 2 or self.replay.shape[1] != len(self.elements)):
            raise SystemExit(f"--replay needs one row of {len(self.elements)} actions per step")
        self.replayed = 0  # rows of `replay` applied so far
        self.started_at = self.done_at = 0.0  # monotonic s: the run period's first exchange, the last step
        self.counters: dict[str, float] = {}  # the C side's, once armed: time waited for actions, calls
        self.native: ctypes.CDLL | None = None  # the C bridge (set by `register`) until it is armed
        self._armed: ctypes.CDLL | None = None  # the C bridge once it steps EnergyPlus
        self._holding = False  # the C bridge holds the initial action through sizing and warm-up (`_hold`)

    # -- setup --------------------------------------------------------------------------------
    def _handles_ready(self, state) -> bool:
        if self.sensor_handles:
            return True
        if not self.x.api_data_fully_ready(state):
            return False
        missing = []
        for s in self.sensors:
            if s.meter:
                h = self.x.get_meter_handle(state, s.variable)
                if h < 0:
                    missing.append(f"meter '{s.variable}'")
            else:
                h = self.x.get_variable_handle(state, s.variable, s.key)
                if h < 0:
                    missing.append(f"variable '{s.variable}' for '{s.key}'")
            self.sensor_handles.append(h)
        for i, elem in enumerate(self.elements):
            for a in elem.actuators:
                h = self.x.get_actuator_handle(state, a.component_type, a.control_type, a.key)
                if h < 0:
                    missing.append(f"actuator '{a.component_type}/{a.control_type}' for '{a.key}'")
                self.actuator_handles.append((h, i))
        names = [s.name for s in self.sensors]
        if self.own is not None:
            self.own_sensors = [names.index(n) for own in self.own for n in own]  # resolve() checked every one
        if self.relinquish and self.node_schedules:
            self.fallback = [names.index(n) if n else -1 for own in self.node_schedules for n in own]
        if missing:
            raise RuntimeError("the model lacks " + "; ".join(missing))
        self.minutes = 60 // self.x.num_time_steps_in_hour(state)  # minutes per zone timestep
        self.step_s = 3600.0 / self.x.num_time_steps_in_hour(state)
        return True

    def _in_run_period(self, state) -> bool:
        return not self.x.warmup_flag(state) and self.x.kind_of_sim(state) == KIND_RUN_PERIOD_WEATHER

    # -- exchange -----------------------------------------------------------------------------
    # Per-step calls go to the C functions pyenergyplus has already typed (`exchange.api`): its Python
    # wrappers re-check every argument, which cost ~5 us a call, about 60 us a step here.
    def _read_sensors(self, state) -> list[float]:
        get = self.x.api.getVariableValue
        if not self.python_only:
            return [get(state, h) for h in self.sensor_handles]
        # A meter's value at the end of a zone timestep is the energy of that timestep (J): as a mean rate, W.
        meter = self.x.api.getMeterValue
        return [
            (meter(state, h) / self.step_s if s.meter else get(state, h)) * s.scale
            for s, h in zip(self.sensors, self.sensor_handles, strict=True)
        ]

    def _time(self, state, at_start: bool = False) -> list[float]:
        c = self.x.api
        if at_start:
            return [c.calendarYear(state), c.dayOfYear(state), 0, 0]
        return [c.calendarYear(state), c.dayOfYear(state), c.hour(state), c.zoneTimeStepNum(state) * self.minutes]

    def _exchange(self, values: list[float]) -> None:
        if self.raw:
            if self.replay is not None and self.replayed < len(self.replay):
                self.action = self.replay[self.replayed].tolist()
                self.replayed += 1
                self.pending = True
            return
        os.write(self.obs_fd, frames.encode(values))
        self.awaiting = True

    def _take_action(self) -> None:
        """The action for the observation last written, read where it is first needed."""
        self.awaiting = False
        code, action = self._actions.read(self._wait, self.spin_s)
        if code != frames.DATA or len(action) != len(self.elements):
            raise ProtocolError(f"expected an action of {len(self.elements)} values, got code {code}")
        self.action = action.tolist()
        self.pending = True

    def _guard(self, state, fn) -> None:
        """Exceptions cannot cross the C callback boundary: record them and stop EnergyPlus."""
        if self.error is not None or self.done:
            return
        try:
            fn(state)
        except BaseException as e:  # noqa: BLE001 - reported to the env as an ERROR frame
            self.error = e
            traceback.print_exc()
            self.api.runtime.stop_simulation(state)

    def apply_action(self, state) -> None:
        self._guard(state, self._apply_action)

    def observe(self, state) -> None:
        self._guard(state, self._observe)

    def _apply_action(self, state) -> None:
        if not self._handles_ready(state):
            return
        if self._holding:  # the C bridge held the warm-up and hands back the run period's first control step
            self._unhold()
        if not self.started and self._in_run_period(state):
            self.started = True
            self.started_at = time.monotonic()
            self._exchange(self._time(state, at_start=True) + self.last_obs)
        if self.awaiting:
            self._take_action()
        if self.relinquish:
            self._apply_or_release(state)
        elif self.pending:
            self.pending = False
            set_value = self.x.api.setActuatorValue
            action = self.action
            if self.own is None:
                for h, i in self.actuator_handles:
                    set_value(state, h, action[i])
            else:
                self._apply_residual(state, set_value)
        if self.native is not None and self.started and not self.python_only:
            self._arm()
        elif not self.started:
            self._hold()

    def _apply_or_release(self, state) -> None:
        """Each actuator set to its action's value, or released to the model's own control where that is NaN (every
        one before the run period: sizing and warm-up run the building's own controls)."""
        set_value, reset = self.x.api.setActuatorValue, self.x.api.resetActuator
        action, fallback, started = self.action, self.fallback, self.started
        for k, (h, i) in enumerate(self.actuator_handles):
            v = action[i] if started else float("nan")
            if v == v:  # not NaN: commanded
                set_value(state, h, v)
            elif fallback and fallback[k] >= 0:  # a node whose scheduled manager the copy dropped: its schedule
                set_value(state, h, self.x.api.getVariableValue(state, self.sensor_handles[fallback[k]]))
            else:  # a node setpoint's other managers write it again before each apply point; a fan's flow and
                reset(state, h)  # a thermostat's schedule return to the model's control
        self.pending = False

    def _apply_residual(self, state, set_value) -> None:
        """Each actuator: its own schedule's value now plus the action's correction (none before the run period:
        sizing and warm-up run the building's own controls), within the action's bounds."""
        get = self.x.api.getVariableValue
        for (h, i), j in zip(self.actuator_handles, self.own_sensors, strict=True):
            e = self.elements[i]
            value = get(state, self.sensor_handles[j]) + (self.action[i] if self.started else 0.0)
            set_value(state, h, min(max(value, e.low), e.high))

    def _observe(self, state) -> None:
        if not self._handles_ready(state):
            return
        if self.awaiting:  # no actuator call since the last observation: still one action per observation
            self._take_action()
        sensors = self._read_sensors(state)
        if not self.started:  # warmup or sizing: keep the latest state for observation 0
            self.last_obs = sensors
            self.pending = True  # re-assert the held action each zone timestep until the run starts
            self._hold()  # the C bridge does this from here on, where there is one
            return
        self.step += 1
        values = self._time(state) + sensors
        if self.step >= self.steps:
            if self.raw:  # the rest of the day would run under the last action; nobody wants it
                self.api.runtime.stop_simulation(state)
            else:
                os.write(self.obs_fd, frames.encode(values, frames.END))
            self.done = True
            self.done_at = time.monotonic()
            return
        self._exchange(values)
