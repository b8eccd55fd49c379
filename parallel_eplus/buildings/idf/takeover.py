"""The agent's node setpoints taken from the model's own setpoint managers, in the prepared copy only (issue 52).

A spec action on a `System Node Setpoint` actuator owns that node's setpoint. In EnergyPlus a SetpointManager that
sets the same node can overwrite the agent's value (the CRAC's `SetpointManager:Warmest` did: the setpoint read back
as the agent's, the coil supplied the manager's), so each run's copy of the model (buildings/idf/prepare.py) drops the
node from every manager that sets the same setpoint there: a manager left with no node is commented out, one that
also sets other nodes keeps them (through a NodeList of its own). Managers that follow the node's setpoint
(`SetpointManager:MixedAir`, `:OutdoorAirPretreat`: their reference node) are kept: they now follow the agent. The
user's file is never edited; `Takeover.lines()` is the report `building check` prints and each worker logs.
"""

from __future__ import annotations

from dataclasses import dataclass

# Per SetpointManager kind (lower case): the index of its "Setpoint Node or NodeList Name" field among the fields
# after the class name (0: its name), and its control variable: the index of its "Control Variable" field, or the
# setpoint it sets when it has none. EnergyPlus 25.2's IDD; the kinds the DOE and ASHRAE prototypes use were
# checked against their field comments.
MANAGERS: dict[str, tuple[int, int | str]] = {
    "setpointmanager:scheduled": (3, 1),
    "setpointmanager:scheduled:dualsetpoint": (4, "dualsetpoint"),
    "setpointmanager:outdoorairreset": (6, 1),
    "setpointmanager:singlezone:reheat": (7, 1),
    "setpointmanager:singlezone:heating": (7, 1),
    "setpointmanager:singlezone:cooling": (7, 1),
    "setpointmanager:singlezone:humidity:minimum": (1, "minimumhumidityratio"),
    "setpointmanager:singlezone:humidity:maximum": (1, "maximumhumidityratio"),
    "setpointmanager:mixedair": (5, 1),
    "setpointmanager:outdoorairpretreat": (10, 1),
    "setpointmanager:warmest": (6, 1),
    "setpointmanager:coldest": (6, 1),
    "setpointmanager:warmesttemperatureflow": (6, 1),
    "setpointmanager:multizone:heating:average": (4, "temperature"),
    "setpointmanager:multizone:cooling:average": (4, "temperature"),
    "setpointmanager:multizone:minimumhumidity:average": (4, "minimumhumidityratio"),
    "setpointmanager:multizone:maximumhumidity:average": (4, "maximumhumidityratio"),
    "setpointmanager:multizone:humidity:minimum": (4, "minimumhumidityratio"),
    "setpointmanager:multizone:humidity:maximum": (4, "maximumhumidityratio"),
    "setpointmanager:followoutdoorairtemperature": (6, 1),
    "setpointmanager:followsystemnodetemperature": (7, 1),
    "setpointmanager:followgroundtemperature": (6, 1),
    "setpointmanager:condenserenteringreset": (9, 1),
    "setpointmanager:condenserenteringreset:ideal": (4, 1),
    "setpointmanager:singlezone:onestagecooling": (4, "temperature"),
    "setpointmanager:singlezone:onestageheating": (4, "temperature"),
    "setpointmanager:returntemperature:chilledwater": (1, "temperature"),
    "setpointmanager:returntemperature:hotwater": (1, "temperature"),
    "setpointmanager:systemnodereset:temperature": (7, 1),
    "setpointmanager:systemnodereset:humidity": (7, 1),
}
# Managers that compute their setpoint from another node's setpoint (field index): they follow the agent's node.
FOLLOWERS = {"setpointmanager:mixedair": 2, "setpointmanager:outdoorairpretreat": 6}
# `System Node Setpoint` control types -> the control variable of a manager setting the same setpoint
ACTUATED = {
    "temperature setpoint": "temperature",
    "temperature minimum setpoint": "minimumtemperature",
    "temperature maximum setpoint": "maximumtemperature",
    "humidity ratio setpoint": "humidityratio",
    "humidity ratio minimum setpoint": "minimumhumidityratio",
    "humidity ratio maximum setpoint": "maximumhumidityratio",
    "mass flow rate setpoint": "massflowrate",
}
DUAL = {"minimumtemperature", "maximumtemperature"}  # what a Scheduled:DualSetpoint manager sets
NODE_SETPOINT = "system node setpoint"


def taken_setpoints(actions) -> tuple[tuple[str, str], ...]:
    """(NODE upper case, control variable) of every `System Node Setpoint` actuator among `actions` (the engine's
    ActionElements or the spec's ActionSpecs), in order, once each."""
    out: dict[tuple[str, str], None] = {}
    for action in actions:
        for a in action.actuators:
            component = getattr(a, "component_type", None) or getattr(a, "component", "")
            control = getattr(a, "control_type", None) or getattr(a, "control", "")
            if component.lower() == NODE_SETPOINT and control.lower() in ACTUATED:
                out[(a.key.upper(), ACTUATED[control.lower()])] = None
    return tuple(out)


@dataclass(frozen=True)
class Replaced:
    """A manager that set a node the agent now sets: removed (it set nothing else) or kept for its other nodes."""

    kind: str
    name: str
    nodes: tuple[str, ...]  # the agent's, as the manager named them
    removed: bool


@dataclass(frozen=True)
class Follower:
    """A manager that follows an agent's node's setpoint (its reference node) and keeps working."""

    kind: str
    name: str
    reference: str


@dataclass(frozen=True)
class Takeover:
    """What the prepared copy changed so that the agent's node setpoints are the agent's (and its outdoor air on
    demand, `ventilation = "demand"`: buildings/idf/ventilation.py)."""

    replaced: tuple[Replaced, ...] = ()
    followers: tuple[Follower, ...] = ()
    unmanaged: tuple[str, ...] = ()  # agent's nodes no manager set (nothing to replace)
    ventilation: tuple[str, ...] = ()  # the demand-controlled ventilation's report lines

    def lines(self) -> list[str]:
        """The prepared-model report: one line per manager replaced or kept following."""
        out = []
        for r in self.replaced:
            what = "removed" if r.removed else "kept for its other nodes"
            out.append(f'{r.kind} "{r.name}" {what}: the agent sets {", ".join(r.nodes)}')
        for f in self.followers:
            out.append(f'{f.kind} "{f.name}" kept: it follows {f.reference}, now the agent\'s setpoint')
        if self.unmanaged:
            out.append(f"no setpoint manager set {', '.join(self.unmanaged)}: nothing replaced there")
        return out + list(self.ventilation)


def scheduled_setpoints(objects) -> dict[str, str]:
    """NODE (upper case) -> the schedule of the `SetpointManager:Scheduled` that sets its temperature: the value the
    model's own controls put on that node each step, which a released node gets back (`relinquish`: its manager is
    gone from the copy, bridge.py writes the schedule instead). NodeLists expanded."""
    lists = {o.fields[0].upper(): o.fields[1:] for o in objects if o.kind.lower() == "nodelist" and o.fields}
    out: dict[str, str] = {}
    for o in objects:
        if o.kind.lower() != "setpointmanager:scheduled" or len(o.fields) <= 3:
            continue
        if "temperature" not in manager_sets(o, 1):
            continue
        for node in lists.get(o.fields[3].upper(), [o.fields[3]]):
            out.setdefault(node.upper(), o.fields[2])
    return out


def manager_sets(o, spec: int | str) -> set[str]:
    """The setpoints a manager object sets (control variables, lower case)."""
    if isinstance(spec, str):
        return DUAL if spec == "dualsetpoint" else {spec}
    value = o.fields[spec].lower() if len(o.fields) > spec and o.fields[spec] else "temperature"
    return {value}


def plan_takeover(objects, taken: tuple[tuple[str, str], ...]) -> tuple[dict[int, tuple[int, list[str]]], Takeover]:
    """For the IDF's `objects` (idf_prep.idf_objects), which managers lose which nodes: {object start: (object end,
    the nodes it keeps)} and the report. Nodes are matched case-insensitively, NodeLists expanded."""
    if not taken:
        return {}, Takeover()
    lists = {o.fields[0].upper(): o.fields[1:] for o in objects if o.kind.lower() == "nodelist" and o.fields}
    wanted: dict[str, set[str]] = {}
    for node, variable in taken:
        wanted.setdefault(node, set()).add(variable)
    changes: dict[int, tuple[int, list[str]]] = {}
    replaced, followers, managed = [], [], set()
    for o in objects:
        kind = o.kind.lower()
        if kind in FOLLOWERS and len(o.fields) > FOLLOWERS[kind] and o.fields[FOLLOWERS[kind]].upper() in wanted:
            followers.append(Follower(o.kind, o.fields[0], o.fields[FOLLOWERS[kind]]))
        if kind not in MANAGERS or len(o.fields) <= MANAGERS[kind][0]:
            continue
        index, variable = MANAGERS[kind]
        sets = manager_sets(o, variable)
        target = o.fields[index]
        nodes = lists.get(target.upper(), [target])
        lost = [n for n in nodes if wanted.get(n.upper(), set()) & sets]
        if not lost:
            continue
        keep = [n for n in nodes if n not in lost]
        managed.update(n.upper() for n in lost)
        changes[o.start] = (o.end, keep)
        replaced.append(Replaced(o.kind, o.fields[0], tuple(lost), not keep))
    unmanaged = tuple(n for n in wanted if n not in managed)
    return changes, Takeover(tuple(replaced), tuple(followers), unmanaged)


def rewrite(text: str, o, keep: list[str], set_fields) -> tuple[str, str]:
    """The manager's new text (commented out when it keeps no node, else pointing at what it keeps) and any NodeList
    object to add for it."""
    if not keep:
        body = text[o.start : o.end]
        lines = "\n".join(f"! {line}" for line in body.splitlines())
        return f"! parallel-eplus: removed in this copy; the agent's action sets its node(s)\n{lines}", ""
    index = MANAGERS[o.kind.lower()][0]
    if len(keep) == 1:
        return set_fields(text, o, {index: keep[0]}), ""
    name = f"{o.fields[0]} nodes kept by parallel-eplus"
    nodelist = "  NodeList,\n" + ",\n".join(f"    {n}" for n in [name, *keep]) + ";  ! set by parallel-eplus"
    return set_fields(text, o, {index: name}), nodelist
