"""Demand-controlled ventilation in the controller's copy of a model (`ventilation = "demand"` in a spec).

Why: the DOE prototypes' packaged units hold their outdoor air at the design occupancy's whenever they run
(`Controller:OutdoorAir`'s fixed minimum on its schedule), and on them the thermostats, the only other knob, save
under 1 % at the same comfort (results/prototypes/). Demand-controlled ventilation is the sequence a supervisory
controller runs there (ASHRAE 62.1's Vbz = Rp * Pz + Ra * Az, as in ASHRAE Guideline 36; 90.1 requires it in
densely occupied spaces): the outdoor air follows the people present. EnergyPlus computes it itself, with the physics
it already has: a `Controller:MechanicalVentilation` with demand-controlled ventilation on sums each zone's
`DesignSpecification:OutdoorAir` over the people its `People` objects hold at that step (a CO2 sensor's ideal).

The copy adds one to each outdoor-air controller that has none, for the zones its air loop serves, and sets the
controller's fixed minimum to 0 so the requested flow governs (an economizer still opens above it). Left as they
are, with the reason in the prepared-model report: a controller with its own, a 100 % outdoor-air unit (a
dedicated outdoor-air system: a minimum-fraction schedule, or the same fixed minimum and maximum), a loop with a
zone whose `Sizing:Zone` names no `DesignSpecification:OutdoorAir` (it would get no outdoor air), and a loop whose
zones have no per-person rate (nothing to follow). The building's own controls (`evaluate --baseline`) run the
model as it is: the measure is the controller's (on_demand.py scores it alone).
"""

from __future__ import annotations

from dataclasses import dataclass

from parallel_eplus.buildings.idf.loops import topology

# Controller:OutdoorAir's fields (after its name): the fixed minimum and maximum flows, the minimum's schedule,
# the minimum-fraction schedule, the mechanical-ventilation controller's name
OA_MIN, OA_MAX, OA_SCHEDULE, OA_MIN_FRACTION, OA_MECHANICAL = 5, 6, 16, 17, 19
SIZING_DSOA = 9  # Sizing:Zone: its Design Specification Outdoor Air Object Name


@dataclass(frozen=True)
class DemandVentilation:
    """What the copy adds: per outdoor-air controller, the fields it sets and the controller it gains."""

    set_fields: tuple[tuple[int, dict[int, str]], ...] = ()  # (the controller's start in the text, field -> value)
    added: tuple[tuple[str, ...], ...] = ()  # each Controller:MechanicalVentilation's fields
    notes: tuple[str, ...] = ()  # the prepared-model report's lines

    def objects(self) -> list[tuple[str, list[str]]]:
        return [("Controller:MechanicalVentilation", list(fields)) for fields in self.added]


def _field(o, i: int) -> str:
    return o.fields[i] if len(o.fields) > i else ""


def _number(value: str) -> float | None:
    try:
        return float(value)
    except ValueError:
        return None


def _per_person(o) -> bool:
    """Whether a DesignSpecification:OutdoorAir has a per-person part (EnergyPlus's defaults: Flow/Person at
    0.00944 m3/s a person), the only part demand-controlled ventilation scales: per area and per zone it is the
    same flow, and a controller with only those keeps the model's own minimum (the midrise apartment's units,
    Flow/Zone: on demand, their flow changed where it had nothing to follow)."""
    method = (_field(o, 1) or "Flow/Person").lower()
    rate = _number(_field(o, 2)) if _field(o, 2) else 0.00944
    return method in ("flow/person", "sum", "maximum") and bool(rate)


def loop_zones(objects) -> dict[str, list[str]]:
    """AIR LOOP (upper case) -> the zones its supply path reaches (splitters and supply plenums, then the air
    terminals on their outlets, then the zone whose inlet nodes hold a terminal's node)."""
    by_kind: dict[str, list] = {}
    for o in objects:
        by_kind.setdefault(o.kind.lower(), []).append(o)
    lists = {o.fields[0].upper(): [f.upper() for f in o.fields[1:]] for o in by_kind.get("nodelist", []) if o.fields}

    def nodes(name: str) -> list[str]:
        return lists.get(name.upper(), [name.upper()])

    zone_of = {n: c.fields[0] for c in by_kind.get("zonehvac:equipmentconnections", []) if len(c.fields) > 2
               for n in nodes(c.fields[2])}  # fmt: skip
    components = {(o.kind.lower(), o.fields[0].upper()): o for o in objects if o.fields}
    paths = {p.fields[1].upper(): p for p in by_kind.get("airloophvac:supplypath", []) if len(p.fields) > 1}
    terminals = [o for o in objects if o.kind.lower().startswith("airterminal:")]
    out: dict[str, list[str]] = {}
    for loop in by_kind.get("airloophvac", []):
        outlets: set[str] = set()
        for inlet in nodes(_field(loop, 8)):
            path = paths.get(inlet)
            f = path.fields[2:] if path else []
            for kind, name in zip(f[::2], f[1::2], strict=False):
                c = components.get((kind.lower(), name.upper()))
                first = 4 if kind.lower() == "airloophvac:supplyplenum" else 2
                outlets |= {n.upper() for n in c.fields[first:]} if c else set()
        zones = [zone_of[n.upper()] for t in terminals if any(f.upper() in outlets for f in t.fields[1:])
                 for n in t.fields[1:] if n.upper() in zone_of]  # fmt: skip
        out[loop.fields[0].upper()] = list(dict.fromkeys(zones))
    return out


def plan_ventilation(text: str, objects) -> DemandVentilation:
    """The copy's demand-controlled ventilation for an IDF text and its objects (idf_prep.idf_objects)."""
    by_name = {o.fields[0].upper(): o for o in objects if o.kind.lower() == "controller:outdoorair" and o.fields}
    zone_lists = {o.fields[0].upper(): o.fields[1:] for o in objects if o.kind.lower() == "zonelist" and o.fields}
    people = {o.fields[0].upper(): _per_person(o) for o in objects
              if o.kind.lower() == "designspecification:outdoorair" and o.fields}  # fmt: skip
    dsoa = {}
    for o in objects:
        if o.kind.lower() == "sizing:zone" and _field(o, SIZING_DSOA):
            for zone in zone_lists.get(o.fields[0].upper(), [o.fields[0]]):
                dsoa[zone.upper()] = o.fields[SIZING_DSOA]
    served = loop_zones(objects)
    sets, added, notes = [], [], []
    for name, _, loop, _ in topology(text).oa_controllers:
        o = by_name[name.upper()]
        zones = served.get((loop or "").upper(), [])
        low, high = _number(_field(o, OA_MIN)), _number(_field(o, OA_MAX))
        why = ("has its own mechanical-ventilation controller" if _field(o, OA_MECHANICAL)
               else "a 100 % outdoor-air unit (a minimum-fraction schedule)" if _field(o, OA_MIN_FRACTION)
               else "a 100 % outdoor-air unit (its minimum is its maximum)" if low is not None and low == high
               else f"its air loop {loop or '(none found)'} reaches no zone" if not zones
               else "zone(s) " + ", ".join(z for z in zones if z.upper() not in dsoa)
               + " have no DesignSpecification:OutdoorAir (Sizing:Zone)"
               if any(z.upper() not in dsoa for z in zones)
               else "its zones' outdoor air does not depend on people (no per-person rate)"
               if not any(people.get(dsoa[z.upper()].upper()) for z in zones) else "")  # fmt: skip
        if why:
            notes.append(f'Controller:OutdoorAir "{name}" kept: {why}')
            continue
        mechanical = f"{name} demand ventilation"
        sets.append((o.start, {OA_MIN: "0.0", OA_MECHANICAL: mechanical}))
        fields = [mechanical, _field(o, OA_SCHEDULE), "Yes", "ZoneSum", "1.0"]
        for z in zones:
            fields += [z, dsoa[z.upper()], ""]
        added.append(tuple(fields))
        notes.append(f'Controller:OutdoorAir "{name}": outdoor air on demand for {", ".join(zones)} '
                     "(Controller:MechanicalVentilation added, its fixed minimum 0)")  # fmt: skip
    return DemandVentilation(tuple(sets), tuple(added), tuple(notes))
