"""Where the state's elements sit in a building's observation: what the model predicts and the served planner reads.

numpy only (the served path): the model's data (model/dataset.py) and the planner share this one layout.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from parallel_eplus.buildings.building import Building


@dataclass(frozen=True)
class Layout:
    """Where the state's elements sit in a building's observation, and the sizes the model needs."""

    sensors: tuple[str, ...]  # the observed sensors' names, in the observation's order
    temperatures: tuple[str, ...]
    energy: tuple[str, ...]
    n_actions: int
    n_exogenous: int
    hvac: tuple[str, ...] = ()  # the energy's observed HVAC parts; the rest of `energy`'s sum is one more part

    @classmethod
    def of(cls, building: Building, n_exogenous: int) -> Layout:
        energy = tuple(e for e in building.comfort.energy if e not in building.temperatures)
        kpis = building.comfort.kpis
        hvac = tuple(c for _, c in kpis.hvac) if kpis is not None else ()
        observed = tuple(o.name for o in building.observed)
        if not all(c in observed and c not in energy for c in hvac):
            hvac = ()  # an HVAC meter the agent does not observe (the office's gas), or HVAC a term itself: no parts
        return cls(observed, building.temperatures, energy, len(building.actions), n_exogenous, hvac)

    @property
    def state_names(self) -> tuple[str, ...]:
        return self.temperatures + (("non_hvac_w", *self.hvac) if self.hvac else self.energy)

    @property
    def n_state(self) -> int:
        return len(self.state_names)

    @property
    def n_inputs(self) -> int:
        return self.n_state + 2 * self.n_actions + self.n_exogenous

    def state(self, obs: np.ndarray) -> np.ndarray:
        """The state from observations (the sensors come first in the observation), [..., n_state]."""
        obs = np.asarray(obs, np.float32)
        if not self.hvac:
            return obs[..., [self.sensors.index(n) for n in self.state_names]]
        temps = obs[..., [self.sensors.index(n) for n in self.temperatures]]
        hvac = obs[..., [self.sensors.index(n) for n in self.hvac]]
        total = obs[..., [self.sensors.index(n) for n in self.energy]].sum(-1, keepdims=True)
        return np.concatenate([temps, total - hvac.sum(-1, keepdims=True), hvac], axis=-1)
