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

import numpy as np

from parallel_eplus.learning.model_based.runtime.layout import Layout

ORIGINS = ("baseline", "explore", "planner", "policy")  # policy: a learner's own steps (mbpo.py)
_FIELDS = ("s", "a_prev", "a", "x", "s_next", "applies", "episode", "step", "origin")


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
