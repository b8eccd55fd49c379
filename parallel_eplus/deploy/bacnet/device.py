"""`parallel-eplus simulate --bacnet ADDRESS`: an EnergyPlus episode of a spec'd building as a BACnet/IP device.

Each sensor the policy reads is an analog input; each setpoint a commandable analog value whose priority array
decides the step: the value at the highest priority holding one is applied, and with none (relinquished at every
priority) that setpoint is left to the building's own controls for the step (`SimulationConfig.relinquish`: the
model's setpoint managers and fan controls, under the actuators). Two clocks: lockstep (a client writes the
`advance` point with the next step's number) or accelerated real time (a step every `step_seconds`).

A watchdog, as a plant's controller would run for a supervisor: the supervisor writes `heartbeat` (the step it
acted on) and `priority` every step; a step it missed relinquishes its priority on every setpoint, so a supervisor
killed without a chance to relinquish leaves no stale command behind.
"""

from __future__ import annotations

import asyncio
import logging
import math
import signal
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from parallel_eplus.buildings.scaling import to_unit
from parallel_eplus.deploy.bacnet import app as bacnet
from parallel_eplus.deploy.bacnet.point_map import PointMap, bacnet_unit
from parallel_eplus.deploy.serve.contract import unit_of
from parallel_eplus.engine.config import SimulationConfig
from parallel_eplus.engine.simulation import Simulation

log = logging.getLogger(__name__)


class Stopped(Exception):
    """The device was asked to stop (SIGINT, SIGTERM) while a step waited for its clock."""


@dataclass
class DeviceConfig:
    """One simulated device: where it listens, what it simulates, its clock."""

    address: str = "127.0.0.1:47808"
    device_id: int = 599
    building: str | None = None  # a spec; None: the paper's data center
    weather: str = "CA"
    days: int = 1
    step_seconds: float | None = None  # accelerated real time: a control step every this many seconds; None: lockstep
    point_map: Path = Path("points.toml")  # written at start: the supervisor reads it
    output_dir: Path | None = None  # the episode's records (steps.parquet), as `evaluate` keeps them
    warmup: str = "initial"  # "initial": EnergyPlus warms up holding the spec's initial action, as in training and
    # `evaluate`; "builtin": under the building's own controls
    watchdog_steps: int = 1  # a supervisor that misses this many steps in a row is relinquished
    linger_s: float = 2.0  # after the last step, answer this long (a supervisor reads `step` == `steps` and leaves)
    name: str = "parallel-eplus"


class Device:
    """The episode (in a worker thread) and its BACnet objects (in the asyncio loop), meeting once a step."""

    def __init__(self, config: DeviceConfig):
        if config.warmup not in ("initial", "builtin"):
            raise ValueError(f"warmup {config.warmup!r}: use initial or builtin")
        if config.step_seconds is not None and config.step_seconds <= 0:
            raise ValueError("--step-seconds must be positive")
        self.config = config
        self.sim = Simulation(self._sim_config(config))  # a bad spec or weather fails here, before any socket
        building = self.sim.building
        observed = zip(building.observed, building.spec.observations, strict=True)
        sensors = [(s.name, unit_of(s.name, o.unit)) for s, o in observed]  # as `export` writes the contract
        setpoints = [(e.name, unit_of(e.name, e.unit), e.low, e.high) for e in self.sim.elements]
        self.map = PointMap.generate(sensors, setpoints, config.step_seconds is None, bacnet.peer(config.address),
                                     config.device_id, 86400 // building.steps_per_day)  # fmt: skip
        self.low = np.array([e.low for e in self.sim.elements])
        self.high = np.array([e.high for e in self.sim.elements])
        self.objects: dict[str, object] = {}
        self.stopping = asyncio.Event()
        self.applied: list[tuple[str | int, ...]] = []  # per step: each setpoint's source (priority, or "own")
        self._missed = 0

    @staticmethod
    def _sim_config(config: DeviceConfig) -> SimulationConfig:
        sim = SimulationConfig(weather=config.weather, building=config.building, run_days=config.days,
                               output_dir=str(config.output_dir) if config.output_dir else None, relinquish=True,
                               native_bridge=False)  # fmt: skip
        if config.warmup == "builtin":
            from parallel_eplus.engine.setup import WorkerSetup

            sim.initial_action = (math.nan,) * len(WorkerSetup.resolve(sim).elements)
        return sim

    # -- BACnet objects ---------------------------------------------------------------------------
    def _make_objects(self, app) -> None:
        from BAC0.core.devices.local.factory import ObjectFactory, analog_input, analog_value, character_string

        bacnet.quiet()  # the factory's loggers, made as it was imported
        ObjectFactory.clear_objects()  # BAC0 keeps them per process
        made = None
        for p in self.map.points:
            units = {"units": bacnet_unit(p.unit)}
            if p.role == "setpoint":  # relinquish default NaN: no command, the building's own control
                desc = f"{p.name} [{p.low}, {p.high}] {p.unit}; relinquished: the building's own control"
                made = analog_value(instance=p.instance, name=p.name, properties=units, presentValue=math.nan,
                                    description=desc, is_commandable=True)  # fmt: skip
            elif p.object_type == "characterstring-value":
                made = character_string(instance=p.instance, name=p.name, presentValue="")
            elif p.object_type == "analog-input":  # `step` -1: no observation yet (EnergyPlus warming up)
                start = -1.0 if p.role == "step" else 0.0
                made = analog_input(instance=p.instance, name=p.name, properties=units, presentValue=start)
            else:
                start = {"advance": 0.0, "heartbeat": -1.0}.get(p.role, 0.0)
                made = analog_value(instance=p.instance, name=p.name, properties=units, presentValue=start)
        made.add_objects_to_application(app)
        self.objects = {p.name: app.this_application.app.get_object_name(p.name) for p in self.map.points}
        for p in self.map.role("setpoint"):
            self._refuse_out_of_range(self.objects[p.name], p)

    @staticmethod
    def _refuse_out_of_range(obj, point) -> None:
        """A command on a setpoint outside its limits [low, high] (as float32, what a REAL carries), or NaN, is
        refused with BACnet's error (property, value-out-of-range), as a controller refuses an impossible command:
        never clamped nor applied. Null (relinquish) passes."""
        from bacpypes3.errors import PropertyError
        from bacpypes3.primitivedata import Null

        write, low, high = obj.write_property, np.float32(point.low), np.float32(point.high)

        async def write_property(attr, value, index=None, priority=None):
            name = attr if isinstance(attr, str) else obj._property_identifier_class(attr).attr
            if name == "presentValue" and value is not None and not isinstance(value, Null):
                v = np.float32(bacnet.real(value))
                if not low <= v <= high:  # NaN too
                    log.warning("refused %s = %s at priority %s: outside [%s, %s] %s (value-out-of-range)",
                                point.name, value, priority or 16, point.low, point.high, point.unit)  # fmt: skip
                    raise PropertyError("value-out-of-range")
            await write(attr, value, index, priority)

        object.__setattr__(obj, "write_property", write_property)

    def _set(self, name: str, value) -> None:
        obj = self.objects[name]
        obj.presentValue = type(obj.presentValue)(value) if not isinstance(value, str) else value

    # -- one step, in the loop --------------------------------------------------------------------
    async def exchange(self, k: int, obs: np.ndarray, info: dict) -> np.ndarray | None:
        """Publish observation `k`, wait for the clock, then read each setpoint: the normalized action (NaN where
        relinquished). None when `k` is the last observation (nothing to act on)."""
        for p, v in zip(self.map.role("sensor"), obs[: len(self.map.role("sensor"))].tolist(), strict=True):
            self._set(p.name, v)
        self.objects["time"].presentValue = info["time"].isoformat()
        self._set("step", k)
        if k == 0:
            self._set("steps", self.sim.steps_per_episode)
        if k >= self.sim.steps_per_episode:
            return None
        await self._wait(k)
        self._watchdog(k)
        return self._action()

    async def _wait(self, k: int) -> None:
        if self.config.step_seconds is None:
            advance = self.objects["advance"]
            while float(advance.presentValue) < k + 1:
                if self.stopping.is_set():
                    raise Stopped
                await asyncio.sleep(0.001)
            return
        deadline = time.monotonic() + self.config.step_seconds  # each observation gets a whole step to be acted on
        while time.monotonic() < deadline:
            if self.stopping.is_set():
                raise Stopped
            await asyncio.sleep(min(0.01, self.config.step_seconds))

    def _watchdog(self, k: int) -> None:
        """A supervisor (its priority written) that has not acted on observation `k` is relinquished after
        `watchdog_steps` such steps in a row."""
        priority = int(bacnet.real(self.objects["priority"].presentValue) or 0)
        if not 1 <= priority <= 16:
            return
        if bacnet.real(self.objects["heartbeat"].presentValue) >= k:
            self._missed = 0
            return
        self._missed += 1
        if self._missed < self.config.watchdog_steps:
            return
        from bacpypes3.basetypes import PriorityValue

        for p in self.map.role("setpoint"):
            self.objects[p.name].priorityArray[priority - 1] = PriorityValue(null=())
        self._set("priority", 0)
        log.warning("the supervisor at priority %d did not act on step %d: its commands relinquished (the "
                    "building's own controls until it writes again)", priority, k)  # fmt: skip

    def _action(self) -> np.ndarray:
        values, sources = [], []
        for p in self.map.role("setpoint"):
            obj = self.objects[p.name]
            held = bacnet.commands(obj.priorityArray)
            if held:
                top = min(held)
                values.append(held[top])
                sources.append(top)
            else:
                values.append(math.nan)
                sources.append("own")
        if not self.applied or self.applied[-1] != tuple(sources):
            log.info("step %d: %s", len(self.applied), ", ".join(
                f"{p.name} {'own control' if s == 'own' else f'priority {s}'}"
                for p, s in zip(self.map.role("setpoint"), sources, strict=True)))  # fmt: skip
        self.applied.append(tuple(sources))
        v = np.array(values, dtype=np.float64)
        return to_unit(v, self.low, self.high)  # NaN stays NaN: released

    # -- the episode, in a thread -----------------------------------------------------------------
    def _episode(self, loop: asyncio.AbstractEventLoop) -> dict:
        def step(k, obs, info):
            return asyncio.run_coroutine_threadsafe(self.exchange(k, obs, info), loop).result()

        try:
            self.sim.launch()
            obs, info = self.sim.first_observation()
            k = 0
            while True:
                self.sim.send(step(k, obs, info))
                obs, _, terminated, info = self.sim.receive()
                k += 1
                if terminated:
                    step(k, obs, info)  # the last readings; `step` == `steps` tells the supervisor it is over
                    return {**info["episode_summary"], "episode_dir": info["episode_dir"]}
        finally:
            self.sim.close()

    async def run(self) -> dict | None:
        """Serve the episode until it ends (its summary) or SIGINT/SIGTERM (None); every socket, process and pipe
        closed on the way out."""
        loop = asyncio.get_running_loop()
        for s in (signal.SIGINT, signal.SIGTERM):
            loop.add_signal_handler(s, self.stopping.set)
        app = None
        try:
            app = await bacnet.start(self.config.address, self.config.device_id, self.config.name)
            self._make_objects(app)
            self.map.write(self.config.point_map)
            clock = "lockstep" if self.config.step_seconds is None else f"a step every {self.config.step_seconds} s"
            log.info("simulating %s (%s, %d days; %s); point map: %s", self.sim.building.spec.name,
                     self.config.weather, self.config.days, clock, self.config.point_map)  # fmt: skip
            episode = asyncio.ensure_future(asyncio.to_thread(self._episode, loop))
            stopping = asyncio.ensure_future(self.stopping.wait())
            await asyncio.wait([episode, stopping], return_when=asyncio.FIRST_COMPLETED)
            self.stopping.set()  # a step waiting for its clock ends; the thread closes the simulation
            try:
                summary = await episode
            except Stopped:
                log.warning("stopped: the episode's records so far are kept")
                return None
            finally:
                stopping.cancel()
            end = time.monotonic() + self.config.linger_s
            while time.monotonic() < end:  # the supervisor reads the last step and relinquishes
                await asyncio.sleep(0.05)
            return summary
        finally:
            for s in (signal.SIGINT, signal.SIGTERM):
                loop.remove_signal_handler(s)
            self.sim.close()
            if app is not None:
                await bacnet.stop(app)


def simulate(config: DeviceConfig) -> dict | None:
    """Run the device (`Device.run`) in its own event loop."""
    return asyncio.run(Device(config).run())
