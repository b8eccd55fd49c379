"""A zone's heating setpoint kept at or below its cooling setpoint, wherever setpoints leave the service.

EnergyPlus stops the run when a dual-setpoint thermostat's heating setpoint is above its cooling setpoint
("DualSetPointWithDeadBand: Effective heating set-point higher than effective cooling set-point"), and bounds that
overlap (a starter's operating rooms: heating 15-21.5 C, cooling 18-30 C) let an agent cross them. One rule for the
simulated loop (engine/actions.py), the exported graph's check and the served answer (deploy/): no imports beyond
the standard library, as a serve-only install has no EnergyPlus and no building specs.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from parallel_eplus.buildings.datacenter import ActionElement


def thermostat_pairs(elements: tuple[ActionElement, ...]) -> tuple[tuple[int, int], ...]:
    """(heating, cooling) indices of the action elements that set the two setpoints of one zone's thermostat."""

    def zones(e: ActionElement, control: str) -> set[str]:
        thermostat = ("zone temperature control", control)
        return {a.key.lower() for a in e.actuators if (a.component_type.lower(), a.control_type.lower()) == thermostat}

    return tuple((h, c) for h, eh in enumerate(elements) for c, ec in enumerate(elements)
                 if zones(eh, "heating setpoint") & zones(ec, "cooling setpoint"))  # fmt: skip


def uncrossed(values, pairs: tuple[tuple[int, int], ...]):
    """`values` (physical setpoints, a list or array row) with each heating setpoint above its paired cooling
    setpoint lowered to it: one rule for the simulated loop, the exported graph's check and the served answer."""
    for h, c in pairs:
        if values[h] > values[c]:  # False where either is NaN (released to the building's own control)
            values[h] = values[c]
    return values
