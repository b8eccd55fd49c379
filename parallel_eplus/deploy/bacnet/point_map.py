"""Where each contract entry lives on a BACnet device: object type, instance and name, in a small TOML file.

`parallel-eplus simulate --bacnet` writes the map of the device it simulates; for a real device, edit the types and
instances (and `device`) to the points its integrator assigned. No BAC0 here: the map is read and checked before
any socket is opened.
"""

from __future__ import annotations

import json
import tomllib
from dataclasses import dataclass, field
from pathlib import Path

# The roles a point plays. sensor: an analog input the supervisor reads; setpoint: a commandable analog value it
# writes at its priority (its relinquish default is the building's own control); time: the building's local date
# and time at the start of the coming step (a character string value, for policies that observe the clock); step:
# the number of the observation the sensors hold; steps: the episode's length (a simulation only); advance: written
# with the next step's number to advance one control step (a lockstep simulation only); heartbeat: the step the
# supervisor last acted on, and its priority, both written every step (the device's watchdog reads them).
ROLES = ("sensor", "setpoint", "time", "step", "steps", "advance", "heartbeat", "priority")
OBJECT_TYPES = ("analog-input", "analog-value", "analog-output", "characterstring-value")
# BACnet engineering units for the contract's units (ASHRAE 135 EngineeringUnits names, as bacpypes3 spells them)
BACNET_UNITS = {"C": "degreesCelsius", "K": "degreesKelvin", "W": "watts", "kg/s": "kilogramsPerSecond",
                "%": "percent", "": "noUnits"}  # fmt: skip
CONTROL_POINTS = {  # role -> (object type, instance): out of the way of the contract's points
    "step": ("analog-input", 1000), "steps": ("analog-input", 1001), "time": ("characterstring-value", 1),
    "advance": ("analog-value", 1000), "heartbeat": ("analog-value", 1001), "priority": ("analog-value", 1002),
}  # fmt: skip


@dataclass
class Point:
    """One BACnet object: what it means to the controller (`role`, `name` as the contract names it) and where it is."""

    name: str
    role: str
    object_type: str
    instance: int
    unit: str = ""
    low: float | None = None  # a setpoint's range (the contract's), for the device's checks and a reader's sake
    high: float | None = None

    @property
    def object_id(self) -> str:
        """As bacpypes3 takes it: "analog-value,3"."""
        return f"{self.object_type},{self.instance}"


@dataclass
class PointMap:
    """Every point of one device, and where the device is (`device`: a BACnet/IP address, "host:port")."""

    points: list[Point] = field(default_factory=list)
    device: str = ""
    device_instance: int | None = None
    control_step_s: int = 900

    def role(self, role: str) -> list[Point]:
        return [p for p in self.points if p.role == role]

    def one(self, role: str) -> Point | None:
        found = self.role(role)
        return found[0] if found else None

    @classmethod
    def generate(cls, sensors: list[tuple[str, str]], setpoints: list[tuple[str, str, float, float]],
                 lockstep: bool, device: str = "", device_instance: int | None = None,
                 control_step_s: int = 900) -> PointMap:  # fmt: skip
        """A simulated device's map: sensors as analog inputs 1..n, setpoints as analog values 1..m, in the
        contract's order; the control points at instances 1000 and up."""
        points = [Point(n, "sensor", "analog-input", i, u) for i, (n, u) in enumerate(sensors, 1)]
        points += [Point(n, "setpoint", "analog-value", i, u, lo, hi) for i, (n, u, lo, hi) in enumerate(setpoints, 1)]
        roles = ["step", "steps", "time", "heartbeat", "priority"] + (["advance"] if lockstep else [])
        points += [Point(r, r, *CONTROL_POINTS[r]) for r in roles]
        return cls(points, device, device_instance, control_step_s)

    def check(self, sensors: list[str], setpoints: list[str]) -> None:
        """Every contract sensor and setpoint has a point of its role; types and roles are known, objects listed
        once. A ValueError names what is wrong and where. (Without a `time` point the supervisor's clock serves.)"""
        for p in self.points:
            if p.role not in ROLES:
                raise ValueError(f"point map: {p.name}: role {p.role!r} is not one of {', '.join(ROLES)}")
            if p.object_type not in OBJECT_TYPES:
                raise ValueError(f"point map: {p.name}: object type {p.object_type!r}; use one of {OBJECT_TYPES}")
        ids = [p.object_id for p in self.points]
        if len(set(ids)) != len(ids):
            raise ValueError(f"point map: an object is listed twice: {sorted({i for i in ids if ids.count(i) > 1})}")
        for role, names in (("sensor", sensors), ("setpoint", setpoints)):
            mapped = [p.name for p in self.role(role)]
            missing = [n for n in names if n not in mapped]
            if missing:
                raise ValueError(f"point map: no {role} point for {', '.join(missing)} (the contract needs them)")

    def to_toml(self) -> str:
        lines = ["# BACnet points of one device (parallel-eplus, docs/bacnet.md). Edit object types and",
                 "# instances to a real device's; `name` is the contract's, `role` what the supervisor does with it.",
                 f"device = {json.dumps(self.device)}"]  # fmt: skip
        if self.device_instance is not None:
            lines.append(f"device_instance = {self.device_instance}")
        lines.append(f"control_step_s = {self.control_step_s}")
        for p in self.points:
            lines += ["", "[[points]]", f"name = {json.dumps(p.name)}", f"role = {json.dumps(p.role)}",
                      f"object = {json.dumps(p.object_type)}", f"instance = {p.instance}"]  # fmt: skip
            if p.unit:
                lines.append(f"unit = {json.dumps(p.unit)}")
            if p.low is not None and p.high is not None:
                lines += [f"low = {p.low!r}", f"high = {p.high!r}"]
        return "\n".join(lines) + "\n"

    def write(self, path: Path) -> Path:
        from parallel_eplus import io

        return io.write_text(path, self.to_toml())

    @classmethod
    def read(cls, path: Path) -> PointMap:
        path = Path(path)
        if not path.is_file():
            raise FileNotFoundError(f"point map {path} not found: `parallel-eplus simulate --bacnet` writes one")
        data = tomllib.loads(path.read_text()) if path.suffix == ".toml" else json.loads(path.read_text())
        try:
            points = [_point(p) for p in data.get("points", [])]
        except KeyError as e:
            raise ValueError(f"{path}: a point lacks {e.args[0]!r} (each has name, role, object, instance)") from None
        step = int(data.get("control_step_s", 900))
        return cls(points, str(data.get("device", "")), data.get("device_instance"), step)


def _point(p: dict) -> Point:
    where = (str(p["object"]), int(p["instance"]))
    return Point(str(p["name"]), str(p["role"]), *where, str(p.get("unit", "")), p.get("low"), p.get("high"))


def bacnet_unit(unit: str) -> str:
    return BACNET_UNITS.get(unit, "noUnits")
