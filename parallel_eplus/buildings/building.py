"""A loaded building spec as the engine uses it: sensors, action elements, bounds and reward signals.

Both sides of the pipe build one from the same spec file (the env process from `SimulationConfig.building`,
the EnergyPlus side from `--building`), so they agree on every name and order by construction.
"""

from __future__ import annotations

import functools
import importlib
import re
from dataclasses import dataclass
from pathlib import Path

from parallel_eplus.buildings import model
from parallel_eplus.buildings.comfort import Comfort
from parallel_eplus.buildings.model import ActionElement, ControlModel, Sensor, action_elements
from parallel_eplus.buildings.spec import BuildingSpec, load_spec


@dataclass(frozen=True)
class Building:
    """A spec resolved for the engine; loaded once per spec file (`load_building` caches it)."""

    spec: BuildingSpec
    sensors: tuple[Sensor, ...]
    actions: tuple[ActionElement, ...]

    @property
    def sensor_names(self) -> tuple[str, ...]:
        return tuple(s.name for s in self.sensors)

    @property
    def temperatures(self) -> tuple[str, ...]:
        return self.spec.reward.temperatures

    @property
    def power(self) -> str:
        return self.spec.reward.power

    @property
    def band(self) -> tuple[float, float]:
        return self.spec.reward.band

    @property
    def steps_per_day(self) -> int:
        return 24 * (self.spec.timesteps_per_hour or timesteps_per_hour(self.spec.idf))

    @functools.cached_property
    def comfort(self) -> Comfort:
        """Its reward signals: zones, band, when the band applies, power and energy (buildings/comfort.py)."""
        return Comfort.of(self.spec, self.steps_per_day // 24)

    def bounds(self) -> tuple[list[float], list[float]]:
        return [s.low for s in self.sensors], [s.high for s in self.sensors]

    def controller_class(self) -> type:
        """The class the spec's `controller = "module:Class"` names: its rule-based controller (`--rbc`)."""
        if not self.spec.controller:
            raise ValueError(
                f'{self.spec.path}: --rbc needs the spec to name a controller (controller = "module:Class")'
            )
        module, _, name = self.spec.controller.partition(":")
        try:
            return getattr(importlib.import_module(module), name)
        except (ImportError, AttributeError) as e:
            raise ValueError(f"{self.spec.path}: controller {self.spec.controller!r} cannot be imported: {e}") from None

    def control(self, model: str = "") -> ControlModel:
        """The spec's agent variant (its IDF, all its actions), or with "baseline" its built-in controls."""
        if model == "baseline":
            return ControlModel("baseline", self.spec.baseline_idf or self.spec.idf, ())
        return ControlModel(self.spec.name, self.spec.idf, self.actions)


def timesteps_per_hour(idf: Path) -> int:
    """The model's own `Timestep` (zone timesteps per hour; EnergyPlus's default, 6, if it has none)."""
    text = re.sub(r"!.*", "", idf.read_text(encoding="latin-1"))
    m = re.search(r"^[ \t]*Timestep,\s*(\d+)\s*;", text, re.MULTILINE | re.IGNORECASE)
    return int(m.group(1)) if m else 6


@functools.cache
def _load(path: Path) -> Building:
    spec = model.DEFAULT if path == model.DEFAULT_SPEC else load_spec(path)
    sensors = tuple(
        Sensor(o.name, o.variable or o.meter or "", o.key or "", o.low, o.high, o.meter is not None, o.scale)
        for o in spec.observations
    )
    return Building(spec, sensors, action_elements(spec))


def load_building(path: str | Path | None = None) -> Building:
    """The building a spec file declares; None: the data center (specs/datacenter-2zone.toml)."""
    from parallel_eplus.buildings.resources import spec_file

    return _load(spec_file(path) if path else model.DEFAULT_SPEC)
