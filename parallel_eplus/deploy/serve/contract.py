"""controller.json: what a deployed controller reads, what it sets, and where it came from; and turning one
request's readings into the observation vector its ONNX graph takes.

No torch here, nor in anything this imports: the server loads this beside onnxruntime alone.
"""

from __future__ import annotations

import datetime as dt
import difflib
import hashlib
import json
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from parallel_eplus.buildings.clock import SCHEDULE_FEATURES, TIME_FEATURES, schedule_features, time_features
from parallel_eplus.buildings.crossing import thermostat_pairs, uncrossed

FORMAT = 1  # a policy's contract; a planner's is 2 (planner_export.py)
READS = 2  # the newest format this version reads
CONTRACT_FILE = "controller.json"
ONNX_FILE = "controller.onnx"
# A sensor's unit when its spec gives none, from its name's suffix (the shipped specs name every sensor this way).
UNIT_SUFFIXES = {"_c": "C", "_w": "W", "_kg_s": "kg/s", "_pct": "%", "_k": "K"}
UNIT_ALIASES = {"c": "C", "°c": "C", "degc": "C", "celsius": "C", "w": "W", "watt": "W", "kg/s": "kg/s"}


class InputError(ValueError):
    """A request the controller refuses: `field` names the reading (or part of the request) at fault."""

    def __init__(self, field: str, message: str, status: int = 422):
        self.field, self.status = field, status
        super().__init__(f"{field}: {message}")


def unit_of(name: str, declared: str = "") -> str:
    if declared:
        return declared
    return next((u for suffix, u in UNIT_SUFFIXES.items() if name.endswith(suffix)), "")


def same_unit(a: str, b: str) -> bool:
    return UNIT_ALIASES.get(a.strip().lower(), a.strip()) == UNIT_ALIASES.get(b.strip().lower(), b.strip())


def sensor_entries(building) -> list[dict]:
    """The contract's readings: each observed sensor with its unit, bounds and where EnergyPlus reads it."""
    return [
        {"name": s.name, "source": "sensor", "variable": s.variable, "key": s.key, "meter": s.meter,
         "unit": unit_of(s.name, o.unit), "low": s.low, "high": s.high, "scale": s.scale}
        for s, o in zip(building.observed, building.spec.observations, strict=True)
    ]  # fmt: skip


def output_entries(building) -> list[dict]:
    """The contract's setpoints: each action with its unit, bounds and the actuators it drives; a zone's heating
    setpoint names the cooling setpoint it is kept at or below (`at_most`), as EnergyPlus requires."""
    entries = [
        {"name": a.name, "unit": unit_of(a.name, a.unit), "low": a.low, "high": a.high,
         "actuators": [{"component": x.component_type, "control": x.control_type, "key": x.key} for x in a.actuators]}
        for a in building.actions
    ]  # fmt: skip
    for h, c in thermostat_pairs(tuple(building.actions)):
        entries[h].setdefault("at_most", []).append(entries[c]["name"])
    return entries


@dataclass
class Contract:
    """controller.json as read back: the raw dict, with the lookups a request needs."""

    data: dict

    @classmethod
    def read(cls, directory: Path) -> Contract:
        path = Path(directory) / CONTRACT_FILE
        if not path.is_file():
            raise FileNotFoundError(f"{path} not found: `parallel-eplus export RUN -o {directory}` writes it")
        data = json.loads(path.read_text())
        if int(data.get("format", 0)) > READS:
            raise ValueError(f"{path}: written by a newer parallel-eplus (format {data['format']})")
        return cls(data)

    @property
    def sensors(self) -> list[dict]:
        return [i for i in self.data["inputs"] if i["source"] == "sensor"]

    @property
    def features(self) -> list[str]:
        return [i["name"] for i in self.data["inputs"] if i["source"] != "sensor"]

    @property
    def outputs(self) -> list[dict]:
        return self.data["outputs"]

    @property
    def needs_time(self) -> bool:
        return bool(self.features)

    def observation(self, body: dict) -> np.ndarray:
        """One request's `{"time": ISO, "sensors": {name: value or {"value", "unit"}}}` as the graph's float32 row.

        Refused, naming the field: a missing, unknown, non-numeric, non-finite or out-of-range reading, a unit
        other than the contract's, a missing or unreadable time where the policy observes the clock."""
        if not isinstance(body, dict):
            raise InputError("body", "must be a JSON object with 'sensors' (and 'time')", 400)
        readings = body.get("sensors")
        if not isinstance(readings, dict):
            raise InputError("sensors", "must be an object of sensor name -> value (physical units)")
        names = [s["name"] for s in self.sensors]
        unknown = sorted(set(readings) - set(names))
        if unknown:
            close = difflib.get_close_matches(unknown[0], names, n=1)
            hint = f"; did you mean {close[0]!r}?" if close else f"; the sensors are {', '.join(names)}"
            raise InputError(f"sensors.{unknown[0]}", f"unknown sensor{hint}")
        values = [self._reading(s, readings) for s in self.sensors]
        if self.needs_time:
            when = self._time(body.get("time"))
            if any(f in TIME_FEATURES for f in self.features):
                values += time_features(when)
            if any(f in SCHEDULE_FEATURES for f in self.features):
                schedule = tuple(tuple(p) for p in self.data["schedule"])
                values += schedule_features(when, schedule)
        return np.array([values], dtype=np.float32)

    @staticmethod
    def _reading(sensor: dict, readings: dict) -> float:
        name, field = sensor["name"], f"sensors.{sensor['name']}"
        if name not in readings:
            raise InputError(field, f"missing (in {sensor['unit'] or 'its unit'})")
        value = readings[name]
        if isinstance(value, dict):
            unit = value.get("unit")
            if unit is not None and not same_unit(str(unit), sensor["unit"]):
                raise InputError(field, f"unit {unit!r}; the controller reads {sensor['unit']!r}")
            value = value.get("value")
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise InputError(field, f"must be a number, got {json.dumps(value)[:40]}")
        if not math.isfinite(value):
            raise InputError(field, f"is {value}; readings must be finite")
        if not sensor["low"] <= value <= sensor["high"]:
            raise InputError(
                field, f"{value} {sensor['unit']} is outside the trained range [{sensor['low']}, {sensor['high']}]"
            )
        return float(value)

    @staticmethod
    def _time(text) -> dt.datetime:
        if not isinstance(text, str):
            raise InputError("time", "required (ISO 8601, local time of the building, the start of the next step)")
        try:
            when = dt.datetime.fromisoformat(text)
        except ValueError:
            raise InputError("time", f"{text[:40]!r} is not an ISO 8601 date and time") from None
        if when.tzinfo is not None:  # the contract knows no site's time zone, nor its daylight saving: never guess
            raise InputError("time", f"{text[:40]!r} has a UTC offset ({when.strftime('%z') or 'Z'}); send the "
                             "building's local standard time without one (e.g. 2021-01-05T10:00:00)")  # fmt: skip
        return when

    @property
    def pairs(self) -> tuple[tuple[int, int], ...]:
        """(heating, cooling) output indices from the outputs' `at_most` (none in contracts written before it)."""
        index = {o["name"]: i for i, o in enumerate(self.outputs)}
        return tuple((h, index[c]) for h, o in enumerate(self.outputs) for c in o.get("at_most", ()))

    def setpoints(self, row: np.ndarray) -> dict[str, dict]:
        row = uncrossed(np.array(row, dtype=float), self.pairs)
        return {o["name"]: {"value": float(v), "unit": o["unit"]} for o, v in zip(self.outputs, row, strict=True)}


def verified_file(directory: Path, entry: dict, what: str) -> Path:
    """A file the contract names (`entry`: its `file` and `sha256`), checked against its hash: a file edited or
    swapped after export is refused."""
    path = Path(directory) / entry["file"]
    if not path.is_file():
        raise FileNotFoundError(f"{path} not found beside {Path(directory) / CONTRACT_FILE}")
    expected = entry.get("sha256")
    if expected and hashlib.sha256(path.read_bytes()).hexdigest() != expected:
        raise ValueError(f"{path} is not the {what} its contract was written for (sha256 differs): export again")
    return path


def load_session(directory: Path, contract: Contract):
    """The controller's onnxruntime session and its (input, output) names; an ONNX file that is not the one its
    contract was exported with (sha256) is refused."""
    import onnxruntime as ort

    onnx_path = verified_file(directory, {"file": ONNX_FILE, **contract.data["onnx"]}, "file")
    options = ort.SessionOptions()
    options.intra_op_num_threads = 1  # one row per call: threads cost more than they give
    session = ort.InferenceSession(str(onnx_path), options, providers=["CPUExecutionProvider"])
    return session, (contract.data["onnx"]["input"], contract.data["onnx"]["output"])
