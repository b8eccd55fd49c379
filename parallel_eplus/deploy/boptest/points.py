"""A building's points as BOPTEST names them: an input `<name>_u` (with `<name>_activate`) per action, a
measurement `<name>_y` per sensor (the observations, then what the KPIs read: thermostat schedules, HVAC meters),
and forecast points from the weather file and the tariffs; each with its minimum, maximum, unit and description.

BOPTEST's units are SI: temperatures in K (the spec's °C converted both ways), powers in W. `<name>` is the spec's
name without its unit suffix (`cooling_setpoint_c` -> `cooling_setpoint_u`), or the whole name where two would
collide.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from parallel_eplus.deploy.serve.contract import UNIT_SUFFIXES, unit_of

KELVIN = 273.15


@dataclass(frozen=True)
class Point:
    """One BOPTEST point: its BOPTEST name, the building's name for it, its unit here and the spec's."""

    name: str
    source: str  # the sensor or action it reads or sets ("" for an activation or a forecast point)
    unit: str | None  # BOPTEST's (SI)
    description: str
    minimum: float | None = None  # in `unit`
    maximum: float | None = None
    spec_unit: str = ""  # the building's own unit (C where `unit` is K)

    def meta(self, bounded: bool = True) -> dict:
        out = {"Description": self.description, "Unit": self.unit}
        if bounded:
            out |= {"Minimum": self.minimum, "Maximum": self.maximum}
        return out

    def to_si(self, value: float) -> float:
        return value + KELVIN if self.spec_unit == "C" else value

    def from_si(self, value: float) -> float:
        return value - KELVIN if self.spec_unit == "C" else value


def si_unit(unit: str) -> str | None:
    return {"C": "K", "": None}.get(unit, unit)


def _base(name: str) -> str:
    return next((name[: -len(s)] for s in UNIT_SUFFIXES if name.endswith(s) and len(name) > len(s)), name)


def _names(names: list[str], suffix: str) -> list[str]:
    """Each name without its unit suffix plus `suffix`; the whole name where two bases would collide."""
    bases = [_base(n) for n in names]
    return [f"{b if bases.count(b) == 1 else n}{suffix}" for n, b in zip(names, bases, strict=True)]


def _bound(value: float, unit: str) -> float | None:
    """A spec bound in SI; None for an open one (the specs write ±1e9 or more for "no bound")."""
    if not math.isfinite(value) or abs(value) >= 1e9:
        return None
    return value + KELVIN if unit == "C" else value


@dataclass(frozen=True)
class Points:
    inputs: tuple[Point, ...]  # the `_u` points, in the building's action order
    measurements: tuple[Point, ...]  # the `_y` points, in the building's sensor order
    forecasts: tuple[Point, ...]

    @classmethod
    def of(cls, building, prices: dict[str, str]) -> Points:
        """`prices`: the electricity price forecast points this building offers (name -> scenario)."""
        actions = building.actions
        units = [unit_of(a.name, a.unit) for a in actions]
        inputs = tuple(
            Point(n, a.name, si_unit(u), _input_text(a), _bound(a.low, u), _bound(a.high, u), u)
            for n, a, u in zip(_names([a.name for a in actions], "_u"), actions, units, strict=True)
        )
        declared = {o.name: o.unit for o in building.spec.observations}
        temps = {s for pair in (building.zone_bounds or ()) for s in pair}
        temps |= {s for own in building.own for s in own if s}
        measurements = []
        for n, s in zip(_names(list(building.sensor_names), "_y"), building.sensors, strict=True):
            u = unit_of(s.name, declared.get(s.name, "")) or ("C" if s.name in temps else "")
            what = f"{s.variable} of {s.key}" if s.key else s.variable
            text = f"{s.name}: {what} (EnergyPlus, the control step's mean{'; a meter' if s.meter else ''})"
            measurements.append(Point(n, s.name, si_unit(u), text, _bound(s.low, u), _bound(s.high, u), u))
        return cls(inputs, tuple(measurements), _forecast_points(prices))

    def activations(self) -> tuple[str, ...]:
        return tuple(activation(p.name) for p in self.inputs)

    def input_meta(self) -> dict:
        out = {}
        for p in self.inputs:
            out[activation(p.name)] = {
                "Description": f"Activation for {p.name}: 1 overwrites it with {p.name}, 0 (the default) leaves "
                "the building's own control in charge",
                "Minimum": None, "Maximum": None, "Unit": None,
            }  # fmt: skip
            out[p.name] = p.meta()
        return out

    def measurement_meta(self) -> dict:
        return {p.name: p.meta() for p in self.measurements}

    def forecast_meta(self) -> dict:
        return {p.name: p.meta(bounded=False) for p in self.forecasts}


def activation(name: str) -> str:
    return name[: -len("_u")] + "_activate"


def _input_text(action) -> str:
    where = ", ".join(f"{a.component_type}/{a.control_type} on {a.key}" for a in action.actuators)
    return f"{action.name}: {where}; not activated: the building's own control"


# BOPTEST's names for the weather and price forecast points (its test cases' `forecast_points`)
WEATHER_POINTS = (
    ("TDryBul", "K", "Outdoor dry bulb temperature (weather file; temperature_uncertainty applies)"),
    ("relHum", "1", "Outdoor relative humidity, 0-1 (weather file)"),
    ("HGloHor", "W/m2", "Global horizontal solar irradiation (weather file; solar_uncertainty applies)"),
)
PRICE_POINTS = {
    "constant": "PriceElectricPowerConstant",
    "dynamic": "PriceElectricPowerDynamic",
    "highly_dynamic": "PriceElectricPowerHighlyDynamic",
}
EMISSIONS_POINT = "EmissionsElectricPower"


def _forecast_points(prices: dict[str, str]) -> tuple[Point, ...]:
    out = [Point(n, "", u, d) for n, u, d in WEATHER_POINTS]
    out += [Point(n, "", "$/kWh", f"Electricity price, {s.replace('_', ' ')} scenario") for n, s in prices.items()]
    out.append(Point(EMISSIONS_POINT, "", "kgCO2/kWh", "Electricity's emission factor"))
    return tuple(out)
