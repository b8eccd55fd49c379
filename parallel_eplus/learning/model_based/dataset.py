"""The model's data: transitions (state, last action, action, exogenous inputs) -> next state, from every source.

The state is what the model predicts: the spec's comfort temperatures and energy terms (the reward's signals), in
physical units. Where the spec's KPIs name the HVAC signals among the sensors (`[kpis] hvac`), the energy is
predicted in parts: those signals, and the rest of the energy terms' sum (a data center's IT load, an office's
lights and plugs), each with its own physics (the IT power falls as its inlet air gets colder, the fans' power
with their flow); summed, they are the spec's energy again. A row pairs the state after step k with the action
applied during step k+1 (normalized to [-1, 1], as the policy's), the action before it, the exogenous inputs at
the end of step k+1 (exogenous.py) and the state then. Each row keeps its origin (the building's own controls,
exploration, the planner), its episode and step, and whether the comfort band applied, so held-out days and
H-step sequences can be drawn.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:  # numpy only at run time: the served planner reads `Layout`
    from parallel_eplus.buildings.building import Building

ORIGINS = ("baseline", "explore", "planner", "policy")  # policy: a learner's own steps (mbpo.py)
_FIELDS = ("s", "a_prev", "a", "x", "s_next", "applies", "episode", "step", "origin")


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


@dataclass
class Transitions:
    """Rows of (s, a_prev, a, x, s_next, applies, episode, step, origin), appended as they come."""

    layout: Layout
    columns: dict[str, list[np.ndarray]] = field(default_factory=dict)

    def add(self, **arrays: np.ndarray) -> None:
        n = len(arrays["s"])
        for name in _FIELDS:
            value = np.asarray(arrays[name])
            if value.shape[:1] != (n,):
                value = np.broadcast_to(value, (n, *value.shape[1:]))
            self.columns.setdefault(name, []).append(value.copy())

    def array(self, name: str) -> np.ndarray:
        parts = self.columns.get(name, [])
        if len(parts) > 1:  # keep one block: appends stay cheap, reads after the first are free
            self.columns[name] = parts = [np.concatenate(parts)]
        return parts[0] if parts else np.zeros(0)

    def __len__(self) -> int:
        return len(self.array("s"))

    def inputs(self, rows=slice(None)) -> tuple[np.ndarray, np.ndarray]:
        """(model inputs, targets): targets are each temperature's change and each energy term's next value."""
        s, s_next = self.array("s")[rows], self.array("s_next")[rows]
        x = np.concatenate([s, self.array("a_prev")[rows], self.array("a")[rows], self.array("x")[rows]], axis=1)
        return x.astype(np.float32), targets(self.layout, s, s_next)

    def held_out(self, block_steps: int, every: int = 5) -> np.ndarray:
        """Rows in held-out blocks (a block is `block_steps` consecutive steps of an episode, e.g. a day): one
        block in `every`, offset by episode, so every weather and season has some."""
        block = self.array("step") // block_steps + self.array("episode")
        return block % every == every - 1

    def sequences(self, rows: np.ndarray, horizon: int) -> np.ndarray:
        """[K, horizon] row indices: runs of `horizon` consecutive steps of one episode, every row in `rows` (a mask).
        Rows of one episode need not be adjacent: workers' steps interleave as they arrive."""
        ep, step = self.array("episode"), self.array("step")
        order = np.lexsort((step, ep))
        ep, step, inside = ep[order], step[order], rows[order]
        n = len(order)
        ok = inside.copy()
        for h in range(1, horizon):
            nxt = np.zeros(n, bool)
            nxt[: n - h] = (ep[h:] == ep[: n - h]) & (step[h:] == step[: n - h] + h) & inside[h:]
            ok &= nxt
        starts = np.flatnonzero(ok)
        return order[starts[:, None] + np.arange(horizon)[None, :]] if len(starts) else np.zeros((0, horizon), int)

    def save(self, path: Path) -> None:
        np.savez_compressed(path, **{name: self.array(name) for name in _FIELDS})

    @classmethod
    def load(cls, path: Path, layout: Layout) -> Transitions:
        with np.load(path) as z:
            data = cls(layout)
            if len(z["s"]):
                data.add(**{name: z[name] for name in _FIELDS})
            return data


def targets(layout: Layout, s: np.ndarray, s_next: np.ndarray) -> np.ndarray:
    k = len(layout.temperatures)
    return np.concatenate([s_next[:, :k] - s[:, :k], s_next[:, k:]], axis=1).astype(np.float32)


def next_state(layout: Layout, s, out):
    """The state after a step from the model's output (`targets`' inverse); numpy or torch."""
    k = len(layout.temperatures)
    if isinstance(s, np.ndarray):
        return np.concatenate([s[..., :k] + out[..., :k], out[..., k:]], axis=-1)
    import torch as th

    return th.cat([s[..., :k] + out[..., :k], out[..., k:]], dim=-1)
