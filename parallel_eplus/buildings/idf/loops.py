"""Where a node sits in a model's HVAC loops and what sets it, read from the IDF, for `building init` (issue 52).

The candidates worth owning are the loops' supply temperatures (an air loop's supply air, a plant or condenser loop's
supply water): Guideline 36's resets act there. `building init` writes them with the loop they belong to, the
managers each run's copy replaces (buildings/idf/takeover.py) and the managers that follow them; and each outdoor-air
controller with the air loop and fans it serves (its flow is the economizer's knob EnergyPlus exposes).
"""

from __future__ import annotations

from dataclasses import dataclass, field

from parallel_eplus.buildings.idf.objects import IdfObject, idf_objects
from parallel_eplus.buildings.idf.takeover import FOLLOWERS, MANAGERS, manager_sets


@dataclass(frozen=True)
class Loop:
    """A loop a node supplies: its kind (AirLoopHVAC, PlantLoop, CondenserLoop) and name; `service`: a plant loop
    serving water use (domestic hot water), not the HVAC."""

    kind: str
    name: str
    service: bool = False
    outlets: tuple[str, ...] = ()  # a plant loop's supply-side components' outlet nodes (its chillers', boilers')

    @property
    def medium(self) -> str:
        return "air" if self.kind.lower() == "airloophvac" else "water"


@dataclass
class Topology:
    """A model's loops as `building init` reads them (node names upper case)."""

    supplies: dict[str, Loop] = field(default_factory=dict)  # a loop's supply-side outlet or setpoint node
    managers: dict[str, list[str]] = field(default_factory=dict)  # node -> 'Kind "name"' setting its temperature
    followers: dict[str, list[str]] = field(default_factory=dict)  # node -> managers following its setpoint
    follows: dict[str, str] = field(default_factory=dict)  # node a follower sets -> the node it follows
    oa_controllers: list[tuple[str, str, str | None, list[str]]] = field(default_factory=list)
    # (controller, its actuator node (the outdoor air inlet), its air loop, the fans on that loop)


def _by_kind(objects: list[IdfObject]) -> dict[str, list[IdfObject]]:
    out: dict[str, list[IdfObject]] = {}
    for o in objects:
        out.setdefault(o.kind.lower(), []).append(o)
    return out


def _components(branch: IdfObject) -> list[tuple[str, str]]:
    """A Branch's (component type, name) pairs: fields after its name and pressure-drop curve, four per component."""
    f = branch.fields[2:]
    return [(f[i], f[i + 1]) for i in range(0, len(f) - 1, 4)]


def _outlets(branch: IdfObject) -> list[str]:
    """A Branch's components' outlet nodes (the fourth field of each component's four)."""
    f = branch.fields[2:]
    return [f[i + 3] for i in range(0, len(f) - 3, 4)]


def topology(text: str) -> Topology:
    """The loops, setpoint managers and outdoor-air controllers of an IDF text."""
    kinds = _by_kind(idf_objects(text))
    lists = {o.fields[0].upper(): o.fields[1:] for o in kinds.get("nodelist", []) if o.fields}
    branch_lists = {o.fields[0].upper(): [b.upper() for b in o.fields[1:]] for o in kinds.get("branchlist", [])}
    branches = {o.fields[0].upper(): _components(o) for o in kinds.get("branch", []) if o.fields}
    outlets = {o.fields[0].upper(): _outlets(o) for o in kinds.get("branch", []) if o.fields}
    t = Topology()
    for o in kinds.get("airloophvac", []):
        for node in lists.get(o.fields[9].upper(), [o.fields[9]]) if len(o.fields) > 9 else []:
            t.supplies[node.upper()] = Loop(o.kind, o.fields[0])
    for kind in ("plantloop", "condenserloop"):
        for o in kinds.get(kind, []):
            demand = branch_lists.get(o.fields[16].upper(), []) if len(o.fields) > 16 else []
            service = any(c.lower() == "wateruse:connections" for b in demand for c, _ in branches.get(b, []))
            supply = branch_lists.get(o.fields[12].upper(), []) if len(o.fields) > 12 else []
            equipment = tuple(dict.fromkeys(n for b in supply for n in outlets.get(b, [])))
            for i in (4, 11):
                if len(o.fields) > i and o.fields[i]:
                    t.supplies[o.fields[i].upper()] = Loop(o.kind, o.fields[0], service, equipment)
    for kind, (index, variable) in MANAGERS.items():
        for o in kinds.get(kind, []):
            if len(o.fields) <= index or "temperature" not in manager_sets(o, variable):
                continue
            reference = o.fields[FOLLOWERS[kind]] if kind in FOLLOWERS and len(o.fields) > FOLLOWERS[kind] else ""
            for node in lists.get(o.fields[index].upper(), [o.fields[index]]):
                t.managers.setdefault(node.upper(), []).append(f'{o.kind} "{o.fields[0]}"')
                if reference:
                    t.follows[node.upper()] = reference
            if reference:
                t.followers.setdefault(o.fields[FOLLOWERS[kind]].upper(), []).append(f'{o.kind} "{o.fields[0]}"')
    loops_by_branch = {b: o.fields[0] for o in kinds.get("airloophvac", []) if len(o.fields) > 4
                       for b in branch_lists.get(o.fields[4].upper(), [])}  # fmt: skip
    oa_systems = {o.fields[1].upper(): o.fields[0].upper() for o in kinds.get("airloophvac:outdoorairsystem", [])
                  if len(o.fields) > 1}  # fmt: skip
    for o in kinds.get("controller:outdoorair", []):
        if len(o.fields) < 5:
            continue
        lists_with = [c.fields[0].upper() for c in kinds.get("airloophvac:controllerlist", [])
                      if o.fields[0].upper() in (f.upper() for f in c.fields[2::2])]  # fmt: skip
        systems = {oa_systems[c] for c in lists_with if c in oa_systems}
        loop = next((loops_by_branch[b] for b, comps in branches.items() if b in loops_by_branch
                     and any(n.upper() in systems for _, n in comps)), None)  # fmt: skip
        fans = [n for b, comps in branches.items() if loops_by_branch.get(b) == loop and loop
                for c, n in comps if c.lower().startswith("fan:")]  # fmt: skip
        t.oa_controllers.append((o.fields[0], o.fields[4], loop, fans))
    return t
