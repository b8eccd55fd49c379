"""`building init`'s air-side and plant candidates (issue 52): loop supply temperatures, fan flows, outdoor air.

- Node setpoints: each loop's supply temperature first (an air loop's supply air, a plant or condenser loop's supply
  water), ready to uncomment: each run's copy of the model replaces the setpoint manager that sets it
  (buildings/idf/takeover.py) and `building check` proves the node follows. Bounds: the range its manager set in the
  short run, widened to Guideline 36's supply-air reset span (12-18 C) for air and by 3 K each way for water. The
  other nodes a manager sets follow; they are listed after, with what they follow.
- Fan flow, as before. EnergyPlus also lists `Fan Pressure Rise` (duct static pressure) but models no duct pressure:
  a lower value cuts fan power and nothing else, a free lunch for an agent, so it is named and not offered.
- Outdoor air: `Outdoor Air Controller / Air Mass Flow Rate`, the economizer's knob EnergyPlus 25.2 exposes (its
  limits, such as the maximum dry-bulb temperature, are inputs with no actuator); the agent's flow replaces the
  economizer and the minimum-outdoor-air logic, so its low bound is the least flow seen while the loop ran.
"""

from __future__ import annotations

import math

from parallel_eplus.buildings.idf.loops import Topology
from parallel_eplus.buildings.starter.survey import NO_SETPOINT, Survey
from parallel_eplus.buildings.starter.toml_text import candidate, clamp, seen_text, snake

SPANS = {  # C: the least range offered, widened to what the short run saw
    "air": (12.0, 18.0),  # Guideline 36's supply-air temperature reset, rounded (12.8-18.3 C)
    "chilled": (5.0, 10.0),  # a chilled-water reset (a 6.7 C design, as the DOE prototypes')
    "hot": (60.0, 82.0),  # a hot-water reset down from an 82 C design
    "condenser": (20.0, 32.0),  # a cooling tower's leaving water, above the chillers' least entering water: not
}  # widened below (a January day's tower water, following the wet bulb, is no lower bound for July)
WATER_MARGIN_K = 3.0  # other water loops: the range seen, this much each way
SETPOINT = "System Node Setpoint Temperature"
SAME_PLAN_K = 0.5  # K: air loops whose supply air the short run saw this close share one knob
AIR_DENSITY = 1.2  # kg/m3, sea level: sized flows (m3/s) as mass flows


def _bounds(loop, v: tuple[float, float]) -> tuple[float, float]:
    """A loop supply temperature's range: its kind's usual reset span, widened to what the short run saw."""
    if loop.medium == "air":
        kind = "air"
    elif loop.kind.lower() == "condenserloop":
        kind = "condenser"
    else:
        kind = "chilled" if v[1] <= 15 else "hot" if v[0] >= 40 else ""
    if not kind:
        return math.floor(v[0] - WATER_MARGIN_K), math.ceil(v[1] + WATER_MARGIN_K)
    low = SPANS[kind][0] if kind == "condenser" else min(math.floor(v[0]), SPANS[kind][0])
    return low, max(math.ceil(v[1]), SPANS[kind][1])


def _same_plan(air: list[str], seen: dict) -> list[list[str]]:
    """The multi-zone air loops gathered by their own plan as the short run saw it: loops whose supply air it saw
    within SAME_PLAN_K at both ends of its range share a knob (the large hotel's two DOAS on an outdoor-air reset,
    18.7-22 C in the run, apart from its 13 C VAV loop; the out-patient's 11.1 C AHU apart from its 12.8 C one)."""
    groups: list[list[str]] = []
    for k in air:
        same = (g for g in groups if all(abs(a - b) <= SAME_PLAN_K for a, b in zip(seen[g[0]], seen[k], strict=True)))
        group = next(same, None)
        if group is None:
            groups.append([k])
        else:
            group.append(k)
    return groups


def _single_zone(manager: str) -> bool:
    return manager.lower().startswith("setpointmanager:singlezone")


def node_candidates(t: Topology, s: Survey, o, zone_nodes: set[str]) -> list[str]:
    """Loop supply temperatures (ready to uncomment), then the other nodes a setpoint manager sets."""
    seen = {k: s.seen.get((SETPOINT, k)) for k in s.keys("OutputVariable", SETPOINT)}
    seen = {k: v for k, v in seen.items() if v and v[0] > NO_SETPOINT and v != (0.0, 0.0) and k not in zone_nodes}
    supplies = [k for k in seen if k in t.supplies and not t.supplies[k].service and k in t.managers]
    lines = ["# ---- loop supply temperatures: each run's copy of the model hands the node to the agent (its setpoint",
             "# manager replaced there, your file untouched); `building check` proves the node follows the action ----",
             ""]  # fmt: skip
    air = [k for k in supplies if t.supplies[k].medium == "air"]
    # A single-zone unit's supply air is its zone thermostat's own loop (SetpointManager:SingleZone:*): one shared
    # value in its place would end every zone's feedback. The knob gathers the loops whose supply air is reset for
    # several zones (scheduled, outdoor-air or warmest resets: Guideline 36's lever).
    single = [k for k in air if all(_single_zone(m) for m in t.managers[k])]
    air = [k for k in air if k not in single]
    if single:
        lines += [
            f"# {len(single)} single-zone unit(s) left out of the together knob: each one's supply air follows",
            "# its own zone's thermostat (SetpointManager:SingleZone:*); own one alone below if you must",
            "",
        ]
    groups = _same_plan(air, seen) if len(air) > 1 else []
    if len(groups) > 1:
        plans = ", ".join(f"{seen[g[0]][0]:.1f}..{seen[g[0]][1]:.1f} C" for g in groups)
        lines += [
            f"# the {len(air)} air loops' own supply air differs (seen {plans}): one knob per own plan, as one",
            "# value for all would hold some loop off its own plan at every step",
            "",
        ]
    for group in groups:  # one knob for the building's supply air, as for its thermostats, per own plan
        low = min(_bounds(t.supplies[k], seen[k])[0] for k in group)
        high = max(_bounds(t.supplies[k], seen[k])[1] for k in group)
        middle = sum(seen[k][0] + seen[k][1] for k in group) / (2 * len(group))
        names = [t.supplies[k].name for k in group]
        if len(groups) == 1:
            name = "supply_air_c"
            note = f"all {len(air)} air loops' supply air together (their managers replaced as below)"
        else:
            span = (min(seen[k][0] for k in group), max(seen[k][1] for k in group))
            loops = "_".join(names) if len(names) <= 2 else f"{names[0]}_and_{len(names) - 1}_more"
            name = f"supply_air_{snake(loops)}_c"
            note = (
                f"all {len(group)} air loops' supply air with one own plan together"
                if len(group) > 1
                else "the one air loop's supply air on its own plan"
            ) + f"{seen_text(span)}: {', '.join(names)}"
        lines += candidate(name, "System Node Setpoint", "Temperature Setpoint", [o(k) for k in group], low, high,
                           clamp(middle, low, high), "C", note)  # fmt: skip
    taken = set(supplies)
    for k in supplies:
        loop, v = t.supplies[k], seen[k]
        low, high = _bounds(loop, v)
        # a plant loop's chillers and boilers control to their own outlets' setpoints where a manager sets them:
        # those nodes go with the loop's (the large office's chillers held 6.7 C whatever its supply node asked)
        equipment = [n for n in loop.outlets if n.upper() in t.managers and n.upper() != k]
        taken.update(n.upper() for n in equipment)
        followers = t.followers.get(k, [])
        managers = [m for n in [k, *(e.upper() for e in equipment)] for m in t.managers[n]]
        note = [f"node {o(k)}: supply {loop.medium} of {loop.kind} {loop.name}{seen_text(v)}",
                f"replaced in each run's copy: {', '.join(managers)}"
                + (f"; following it: {len(followers)} ({followers[0]}, ...)" if followers else "")]  # fmt: skip
        if equipment:
            note.append(f"with its equipment's outlets, which it controls to: {', '.join(equipment)}")
        keys = [o(k), *equipment] if equipment else o(k)
        lines += candidate(f"{snake(o(k))}_setpoint_c", "System Node Setpoint", "Temperature Setpoint", keys, low, high,
                           clamp((v[0] + v[1]) / 2, low, high), "C", note)  # fmt: skip
    others = [k for k in seen if k not in taken]
    if others:
        lines += ["# ---- other nodes with a setpoint: most follow a supply node above (own that instead) ----", ""]
    for k in others:
        v = seen[k]
        low, high = min(10.0, math.floor(v[0])), max(30.0, math.ceil(v[1]))
        by = t.managers.get(k)
        what = f"set by {', '.join(by)}" if by else "no setpoint manager in the IDF sets it"
        if k in t.follows:
            what += f", following {t.follows[k]}"
        if k in t.supplies and t.supplies[k].service:
            what += f" (service water: {t.supplies[k].kind} {t.supplies[k].name}, not HVAC)"
        lines += candidate(f"{snake(o(k))}_setpoint_c", "System Node Setpoint", "Temperature Setpoint", o(k), low, high,
                           clamp((v[0] + v[1]) / 2, low, high), "C", f"node {o(k)}{seen_text(v)}: {what}")  # fmt: skip
    return lines


def _design_kg_s(s: Survey, fan: str) -> float:
    """A fan's sized maximum flow (eplusout.eio), in kg/s at sea-level air density; 0 if EnergyPlus reported none."""
    sized = [
        v
        for (kind, name, what), v in s.sizing.items()
        if kind.lower().startswith("fan:") and name == fan.upper() and "Maximum" in what and "m3/s" in what
    ]
    return round(AIR_DENSITY * max(sized), 2) if sized else 0.0  # fmt: skip


def fan_candidates(s: Survey, o) -> list[str]:
    """Each fan's mass flow, up to the larger of its sized maximum and the short run's; a note on the pressure-rise
    actuator EnergyPlus lists."""
    lines = []
    for key in s.keys("Actuator", "Fan", "Fan Air Mass Flow Rate"):
        v = s.seen.get(("Fan Air Mass Flow Rate", key))
        seen, design = (round(v[1], 2) if v and v[1] > 0 else 0.0), _design_kg_s(s, key)
        top = max(seen, design) or 1.0
        note = f"fan {o(key)}: at most {seen} kg/s in the short run" + (
            f", sized for {design} kg/s" if design else "; check its maximum flow in the IDF"
        )
        lines += candidate(f"{snake(o(key))}_kg_s", "Fan", "Fan Air Mass Flow Rate", o(key), round(0.25 * top, 2),
                           top, top, "kg/s", note)  # fmt: skip
    pressure = s.keys("Actuator", "Fan", "Fan Pressure Rise")
    if pressure:
        n = len(pressure)
        lines += [f"# Fan / Fan Pressure Rise (duct static pressure) is listed for {n} fan(s), not offered: EnergyPlus",
                  "# models no duct pressure, so a lower value cuts fan power and changes nothing else.",
                  ""]  # fmt: skip
    return lines


def _least_while_running(s: Survey, node: str, fans: list[str]) -> float:
    """The outdoor-air flow the model's own controls kept while its loop's fans ran (above a tenth of their largest
    flow): its 5th percentile, kg/s; 0 if nothing ran."""
    flows = s.series.get(("System Node Mass Flow Rate", node.upper()), [])
    fan = [s.series.get(("Fan Air Mass Flow Rate", f.upper()), []) for f in fans]
    fan = [sum(values) for values in zip(*fan, strict=False)] if fan and all(fan) else []
    top = max(fan, default=0.0)
    running = sorted(q for q, f in zip(flows, fan, strict=False) if top > 0 and f > 0.1 * top)
    return round(running[len(running) // 20], 3) if running else 0.0


def economizer_candidates(t: Topology, s: Survey, o) -> list[str]:
    """Each outdoor-air controller's flow EnergyPlus lets an agent set, with the loop and fans it serves."""
    listed = set(s.keys("Actuator", "Outdoor Air Controller", "Air Mass Flow Rate"))
    lines = []
    for name, node, loop, fans in t.oa_controllers:
        if name.upper() not in listed:
            continue
        flow = "System Node Mass Flow Rate"
        v = s.seen.get((flow, node.upper()))
        fan_top = sum(max(_design_kg_s(s, f), s.seen.get(("Fan Air Mass Flow Rate", f.upper()), (0.0, 0.0))[1])
                      for f in fans)  # fmt: skip
        high = round(max(fan_top, v[1] if v else 0.0), 2) or 1.0
        low = min(_least_while_running(s, node, fans), high)
        note = [f"outdoor air of {loop or 'its air loop'} through {o(name)}{seen_text(v, 'kg/s')}",
                "the agent's flow replaces the economizer and the minimum-outdoor-air logic: ventilation is its",
                "low: the least its own controls kept while the fans ran; high: the fans' largest "
                f"({fan_top:.2f} kg/s)"]  # fmt: skip
        lines += candidate(f"{snake(o(name))}_oa_kg_s", "Outdoor Air Controller", "Air Mass Flow Rate", o(name), low,
                           high, low, "kg/s", note, readback=(flow, o(node)))  # fmt: skip
    return lines
