"""`parallel-eplus serve DIR --bacnet ADDRESS`: an exported controller as a BACnet supervisor (onnxruntime, BAC0).

Every control step it reads the contract's points from the device (one ReadPropertyMultiple: the sensors, the
time, each setpoint's priority array), computes the setpoints with controller.onnx (an exported planner: its
runtime, bacnet_planner.py) and writes them at its priority
(default 8; 1-7 are refused: ASHRAE 135 practice keeps them for life safety and critical equipment). It gives the
building back (null at its priority, so the device's own control resumes) on SIGINT/SIGTERM, on an error it cannot
recover from, and for a step whose answer is a fallback (a reading the policy cannot take). A command found at a
higher priority, or someone else's at its own, is an operator's override: logged, and not fought.
"""

from __future__ import annotations

import asyncio
import datetime as dt
import logging
import signal
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from parallel_eplus.deploy.bacnet import app as bacnet
from parallel_eplus.deploy.bacnet.point_map import PointMap
from parallel_eplus.deploy.serve.contract import Contract, InputError
from parallel_eplus.deploy.serve.runtime import PolicyRuntime

log = logging.getLogger(__name__)

PROBE_S = 3  # at start, a Who-Is and a read of the device's points each wait this long before saying why not


@dataclass
class SupervisorConfig:
    """Which controller, which device and points, at which priority, from which local address."""

    controller: Path
    device: str  # the device's BACnet/IP address, "host[:port]"
    point_map: Path
    priority: int = 8
    local: str | None = None  # this supervisor's own address, "host[/mask][:port]"; None: the device's host, port+1
    device_id: int = 598  # this supervisor's own BACnet device instance
    bbmd: str | None = None  # register as a foreign device with this BBMD ("host[:port]") to reach another subnet
    bbmd_ttl: int = 900
    poll_s: float = 0.005  # how often to look for the device's next step
    give_up_s: float = 60.0  # the device silent this long: give the building back and exit
    advance: bool = True  # a lockstep device (its map has `advance`): write the next step's number after acting
    step_seconds: float | None = None  # a device without a `step` point: act every this many s (default: the map's
    # control_step_s)

    def __post_init__(self):
        if not 8 <= self.priority <= 16:
            raise ValueError(
                f"--priority {self.priority}: a supervisor writes at 8-16; 1-7 are for life safety, critical "
                "equipment and minimum on/off (ASHRAE 135 practice), which a learned controller must never override"
            )


class Supervisor:
    """Reads, computes and writes once per device step; owns its priority's slot and nothing else."""

    def __init__(self, config: SupervisorConfig):
        self.config = config
        self.contract = Contract.read(config.controller)
        self.planner = None  # an exported planner (`kind: planner`): each step the request its HTTP client sends
        if self.contract.data.get("kind") == "planner":
            from parallel_eplus.deploy.bacnet.planner import PlannerSteps

            self.planner = PlannerSteps(config.controller, self.contract)
        else:
            self.policy = PolicyRuntime(config.controller, self.contract)
        self.map = PointMap.read(config.point_map)
        names = [o["name"] for o in self.contract.outputs]
        extra = self.planner.points if self.planner else []  # a planner's rule reads points beyond the sensors
        self.map.check([s["name"] for s in self.contract.sensors] + extra, names)
        if self.contract.needs_time and self.map.one("time") is None:
            log.info("no `time` point: the policy's clock features from this machine's local time")
        by_name = {p.name: p for p in self.map.points}
        self.sensors = [by_name[s["name"]] for s in self.contract.sensors]
        self.extra = [by_name[n] for n in extra]
        self.setpoints = [next(p for p in self.map.role("setpoint") if p.name == n) for n in names]
        self.device = bacnet.peer(config.device)
        self.written: dict[str, float] = {}  # our command on each point (float32, as the device holds it)
        self.overridden: dict[str, int] = {}  # point -> the priority overriding us
        self.stopping = asyncio.Event()
        self.acted = self.fallbacks = 0
        self.app = None

    # -- the device ---------------------------------------------------------------------------------
    async def read(self) -> dict:
        """One ReadPropertyMultiple: {point name: value} (setpoints: their priority arrays as {priority: value})."""
        from bacpypes3.pdu import Address
        from bacpypes3.primitivedata import ObjectIdentifier

        wanted = [*self.sensors, *self.extra, *(p for r in ("step", "steps", "time") if (p := self.map.one(r)))]
        request: list = []
        for p in wanted:
            request += [ObjectIdentifier(p.object_id), ["present-value"]]
        for p in self.setpoints:
            request += [ObjectIdentifier(p.object_id), ["priority-array"]]
        answer = await self.app.this_application.app.read_property_multiple(Address(self.device), request)
        names = {(p.object_type, p.instance): p for p in [*wanted, *self.setpoints]}
        out = {}
        for (otype, instance), prop, _, value in answer:
            p = names[(str(otype), int(instance))]
            out[p.name] = bacnet.commands(value) if str(prop) == "priority-array" else value
        return out

    async def write(self, point, value, priority: int | None = None) -> None:
        from bacpypes3.pdu import Address
        from bacpypes3.primitivedata import Null, ObjectIdentifier, Real

        v = Null(()) if value is None else Real(value)
        app = self.app.this_application.app
        await app.write_property(Address(self.device), ObjectIdentifier(point.object_id), "present-value", v,
                                 priority=priority)  # fmt: skip

    async def probe(self, local: str) -> bool:
        """Whether the device answers a read of its points within PROBE_S; if not, say at once why it might not,
        from whether it answered a Who-Is (I-Am) meanwhile (the loop keeps trying until `give_up_s`)."""
        from bacpypes3.apdu import ErrorRejectAbortNack
        from bacpypes3.pdu import Address

        i_am = asyncio.ensure_future(self.app.this_application.app.who_is(address=Address(self.device),
                                                                          timeout=PROBE_S))  # fmt: skip
        try:
            await asyncio.wait_for(self.read(), timeout=PROBE_S)
        except (TimeoutError, OSError, ErrorRejectAbortNack) as e:
            error = e
        else:
            i_am.cancel()
            return True
        try:
            heard = await asyncio.wait_for(i_am, timeout=PROBE_S)
        except (TimeoutError, asyncio.CancelledError):
            heard = []
        instances = sorted({int(i.iAmDeviceIdentifier[1]) for i in heard})
        host, _, port = bacnet.split_address(self.device)
        l_host, _, l_port = bacnet.split_address(local)
        shared = l_port == port and l_host != host  # e.g. 127.0.0.2:P beside a device on 127.0.0.1:P
        again = f"Trying again until {self.config.give_up_s:.0f} s without an answer"
        if instances == [self.config.device_id] or shared and not heard:
            log.error("the device at %s does not answer: %s (--local %s:%d on the device's own port, on one machine, "
                      "shares its socket for broadcasts, so the requests reach this supervisor's own socket): give "
                      "--local another port (the default is the device's port + 1). %s", self.device,
                      "this supervisor answers its own Who-Is and reads" if heard else "no I-Am, no read",
                      l_host, l_port, again)  # fmt: skip
        elif heard:
            log.error("the device at %s answers a Who-Is (I-Am from device %s) but not a read of the point map's "
                      "points in %d s (%s): is %s this device's map (object types and instances)? %s", self.device,
                      ", ".join(map(str, instances)), PROBE_S, error, self.config.point_map, again)  # fmt: skip
        else:
            log.error("the device at %s answered neither a Who-Is (no I-Am) nor a read in %d s: is a device running at "
                      "that address and port, and does UDP reach it from %s:%d (a firewall, another subnet: --bbmd)? "
                      "%s", self.device, PROBE_S, l_host, l_port, again)  # fmt: skip
        return False

    # -- one step -----------------------------------------------------------------------------------
    def answer(self, state: dict) -> np.ndarray | None:
        """The controller's setpoints for the readings, or None (a fallback) where it cannot take them."""
        body = {"sensors": {p.name: float(state[p.name]) for p in self.sensors}}
        if self.contract.needs_time or self.planner:  # the device's clock, else ours: when the coming step starts
            body["time"] = str(state.get("time") or dt.datetime.now().isoformat(timespec="seconds"))
        if self.planner:
            extra = {p.name: float(state[p.name]) for p in self.extra}
            return self.planner.answer(body["sensors"], extra, body["time"], state.get("step"))
        try:
            row = self.policy.setpoint_row(body)
        except InputError as e:
            log.warning("fallback at step %s: %s; the building's own controls act", state.get("step"), e)
            return None
        return row if np.all(np.isfinite(row)) else None

    def _override(self, point, held: dict[int, float]) -> int | None:
        """The priority of a command that overrides ours on `point` (None: ours stands or the slot is free)."""
        mine = self.config.priority
        higher = [p for p in held if p < mine]
        if higher:
            return min(higher)
        if mine in held and np.float32(held[mine]) != np.float32(self.written.get(point.name, np.nan)):
            return mine  # someone else's value in our slot: an operator at our priority
        return None

    async def act(self, state: dict) -> None:
        k = int(bacnet.real(state["step"]))
        row = self.answer(state)
        if row is None:
            self.fallbacks += 1
            await self.relinquish()
        for p, value in zip(self.setpoints, [] if row is None else row.tolist(), strict=False):
            by = self._override(p, state[p.name])
            if by is not None and self.overridden.get(p.name) != by:
                log.warning("%s is overridden at priority %d (value %.3f): not fighting it%s", p.name, by,
                            state[p.name][by], "; ours stays current below it" if by < self.config.priority else
                            ": someone else's command in our slot, left alone")  # fmt: skip
            elif by is None and self.overridden.get(p.name) is not None:
                log.info("%s: the override is gone; priority %d acts again", p.name, self.config.priority)
            if by is None:
                self.overridden.pop(p.name, None)
                await self.write(p, value, self.config.priority)
                self.written[p.name] = float(np.float32(value))
                continue
            self.overridden[p.name] = by
            if by == self.config.priority:
                self.written.pop(p.name, None)  # never write, nor relinquish, a slot someone else holds
                continue
            await self.write(p, value, self.config.priority)  # below a higher priority's command: not fighting it
            self.written[p.name] = float(np.float32(value))
        self.acted += 1
        control = {"heartbeat": k, "priority": self.config.priority, "advance": k + 1 if self.config.advance else None}
        for role, value in control.items():  # what the device's watchdog reads; the lockstep clock
            if value is not None and (point := self.map.one(role)) is not None:
                await self.write(point, float(value))

    async def relinquish(self) -> None:
        """Null at our priority on every point we hold: the device's own control (or a lower priority) resumes."""
        for p in self.setpoints:
            if p.name in self.written:
                await self.write(p, None, self.config.priority)
                del self.written[p.name]

    # -- the loop -----------------------------------------------------------------------------------
    async def run(self) -> int:
        """Supervise until the device's episode ends (0), SIGINT/SIGTERM (0) or the device is lost (1)."""
        loop = asyncio.get_running_loop()
        for s in (signal.SIGINT, signal.SIGTERM):
            loop.add_signal_handler(s, self.stopping.set)
        host, _, port = bacnet.split_address(self.device)
        local = self.config.local or f"{host}:{port + 1}"
        from bacpypes3.apdu import ErrorRejectAbortNack

        code, last, heard = 0, None, time.monotonic()
        try:
            self.app = await bacnet.start(local, self.config.device_id, "parallel-eplus supervisor", self.config.bbmd,
                                          self.config.bbmd_ttl)  # fmt: skip
            log.info("supervising %s at priority %d with %s (%s)", self.device, self.config.priority,
                     self.config.controller, self.contract.data["policy"]["run"])  # fmt: skip
            await self.probe(local)  # a device that cannot be reached is said so within seconds, with why
            timer = self.map.one("step") is None  # a real device: our own clock, a step every control step
            period = self.config.step_seconds or self.map.control_step_s
            tick = time.monotonic()
            while not self.stopping.is_set():
                if timer and time.monotonic() < tick:
                    await asyncio.sleep(min(0.1, tick - time.monotonic()))
                    continue
                try:
                    state = await asyncio.wait_for(self.read(), timeout=10)
                    heard = time.monotonic()
                except (TimeoutError, OSError, ErrorRejectAbortNack) as e:
                    if time.monotonic() - heard > self.config.give_up_s:
                        log.error("the device at %s has not answered for %.0f s (%s): giving up", self.device,
                                  self.config.give_up_s, e)  # fmt: skip
                        code = 1
                        break
                    await asyncio.sleep(1.0)
                    continue
                if timer:
                    state["step"], tick = self.acted, tick + period
                step, steps = state.get("step"), state.get("steps")
                if steps is not None and bacnet.real(step) >= bacnet.real(steps) > 0:
                    log.info("the device's episode is over (step %d)", int(bacnet.real(step)))
                    break
                if step == last or bacnet.real(step) < 0:  # no new observation (-1: the device is still starting)
                    await asyncio.sleep(self.config.poll_s)
                    continue
                await self.act(state)
                last = step
        except Exception:
            log.exception("supervisor failed")
            code = 1
        finally:
            await self._shutdown(loop)
        log.info("acted on %d steps (%d fallbacks)", self.acted, self.fallbacks)
        return code

    async def _shutdown(self, loop) -> None:
        for s in (signal.SIGINT, signal.SIGTERM):
            loop.remove_signal_handler(s)
        if self.app is None:
            return
        try:
            held = bool(self.written)
            await asyncio.wait_for(self.relinquish(), timeout=10)
            if held:
                log.info("relinquished priority %d: the building's own controls act", self.config.priority)
            if self.acted and (point := self.map.one("priority")) is not None:  # gone: nothing for a watchdog
                await asyncio.wait_for(self.write(point, 0.0), timeout=10)
        except Exception as e:  # noqa: BLE001 - the device may be gone; nothing more can be done from here
            log.error("could not relinquish priority %d (%s): the device's watchdog must", self.config.priority, e)
        await bacnet.stop(self.app)


def supervise(config: SupervisorConfig) -> int:
    return asyncio.run(Supervisor(config).run())
