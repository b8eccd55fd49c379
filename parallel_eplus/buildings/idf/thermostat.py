"""Each zone's comfort bounds as the model was designed: the schedules its own thermostat follows.

BOPTEST scores thermal discomfort against each zone's own lower and upper setpoints, which follow its occupied and
unoccupied schedules. An EnergyPlus model says the same in its `ZoneControl:Thermostat` objects: a zone (or zone
list) and its `ThermostatSetpoint:*` object, whose heating and cooling setpoint schedules are read each step
(`Schedule Value`, like any sensor). The schedules keep their values when an agent actuates the thermostat
(`Zone Temperature Control`), so the bounds are the design's, not the agent's.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

from parallel_eplus.buildings.idf.objects import IdfObject, idf_objects

SCHEDULE_VARIABLE = "Schedule Value"


@dataclass(frozen=True)
class ZoneSetpoints:
    """A zone's heating (lower) and cooling (upper) setpoint schedule names; None: no such side."""

    zone: str
    heating: str | None
    cooling: str | None


def sensor_name(schedule: str) -> str:
    """The hidden sensor reading a setpoint schedule (step table column)."""
    return "setpoint_" + re.sub(r"[^a-z0-9]+", "_", schedule.lower()).strip("_")


def zone_setpoints(idf: Path | list[IdfObject]) -> dict[str, ZoneSetpoints]:
    """Zone name (upper-case) -> its thermostat's setpoint schedules, for every zone a thermostat controls. `idf`:
    the model's file, or its objects parsed already."""
    objects = idf if isinstance(idf, list) else idf_objects(Path(idf).read_text(encoding="latin-1"))
    by_kind: dict[str, dict[str, list[str]]] = {}
    for o in objects:
        if o.fields:
            by_kind.setdefault(o.kind.lower(), {})[o.fields[0].upper()] = o.fields
    zone_lists = {k: [z for z in f[1:] if z] for k, f in by_kind.get("zonelist", {}).items()}
    out: dict[str, ZoneSetpoints] = {}
    for fields in by_kind.get("zonecontrol:thermostat", {}).values():
        if len(fields) < 5:
            continue
        heating = cooling = None
        for kind, name in zip(fields[3::2], fields[4::2], strict=False):  # (object type, name) pairs
            f = by_kind.get(kind.lower(), {}).get(name.upper())
            if not f:
                continue
            k = kind.lower()
            if k == "thermostatsetpoint:dualsetpoint" and len(f) >= 3:
                heating, cooling = f[1] or heating, f[2] or cooling
            elif k == "thermostatsetpoint:singleheating" and len(f) >= 2:
                heating = heating or f[1]
            elif k == "thermostatsetpoint:singlecooling" and len(f) >= 2:
                cooling = cooling or f[1]
            elif k == "thermostatsetpoint:singleheatingorcooling" and len(f) >= 2:
                heating, cooling = heating or f[1], cooling or f[1]
        if heating is None and cooling is None:
            continue
        target = fields[1]
        for zone in zone_lists.get(target.upper(), [target]):
            out[zone.upper()] = ZoneSetpoints(zone, heating, cooling)
    return out
