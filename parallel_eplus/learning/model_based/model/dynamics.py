"""The learned model: an ensemble of small MLPs, one control step ahead, all members in one batched forward.

Each member is a 2-layer SiLU MLP over the normalized inputs (dataset.py: state, last action, action, exogenous)
predicting the normalized targets (each temperature's change, each energy term's next value), trained on its own
bootstrap of the rows (Chua et al. 2018, PETS). The members' weights are stacked ([members, in, out]), so one
`torch.baddbmm` per layer evaluates every member on every candidate of every worker: the planner's forward is
one call per horizon step, whatever the number of workers.
"""

from __future__ import annotations

import logging
from dataclasses import asdict

import numpy as np
import torch as th

from parallel_eplus.learning.model_based.model.dataset import Layout, Transitions, next_state
from parallel_eplus.learning.model_based.runtime.ensemble_graph import EnsembleArrays
from parallel_eplus.learning.model_based.settings import MPCSettings

log = logging.getLogger(__name__)


class Ensemble(th.nn.Module):
    """`members` MLPs with stacked weights; inputs and targets normalized by statistics fitted on the data."""

    def __init__(self, layout: Layout, settings: MPCSettings, seed: int = 0):
        super().__init__()
        self.layout, self.settings = layout, settings
        gen = th.Generator().manual_seed(seed)
        e, h, n_in, n_out = settings.members, settings.hidden, layout.n_inputs, layout.n_state
        sizes = [(n_in, h), (h, h), (h, n_out)]
        self.weights = th.nn.ParameterList(
            [th.nn.Parameter(th.randn(e, a, b, generator=gen) * (1 / a) ** 0.5) for a, b in sizes]
        )
        self.biases = th.nn.ParameterList([th.nn.Parameter(th.zeros(e, 1, b)) for _, b in sizes])
        for name, size in (("x_mean", n_in), ("x_std", n_in), ("y_mean", n_out), ("y_std", n_out)):
            self.register_buffer(name, th.zeros(size) if "mean" in name else th.ones(size))
        self.fitted_rows = 0
        self._gen = gen

    def forward(self, x: th.Tensor) -> th.Tensor:
        """Normalized inputs [members, batch, in] -> normalized outputs [members, batch, out]."""
        for i, (w, b) in enumerate(zip(self.weights, self.biases, strict=True)):
            x = th.baddbmm(b, x, w)
            if i < len(self.weights) - 1:
                x = th.nn.functional.silu(x)
        return x

    def step(self, s: th.Tensor, a_prev: th.Tensor, a: th.Tensor, x: th.Tensor) -> th.Tensor:
        """Each member's next state, [members, batch, n_state], from physical states [members, batch, n_state]
        (one trajectory per member) and actions and exogenous inputs [batch, ...] shared by the members."""
        e = s.shape[0]
        shared = th.cat([a_prev, a, x], dim=-1).expand(e, -1, -1)
        inputs = (th.cat([s, shared], dim=-1) - self.x_mean) / self.x_std
        out = self(inputs) * self.y_std + self.y_mean
        return next_state(self.layout, s, out)

    # -- fitting --------------------------------------------------------------------------------
    def fit(self, data: Transitions, rows: np.ndarray, epochs: int) -> float:
        """Fit every member on its own bootstrap of `rows` (the statistics are refitted first); returns the last
        epoch's mean training loss (normalized MSE)."""
        x, y = data.inputs(rows)
        self.x_mean.copy_(th.as_tensor(x.mean(0)))
        self.x_std.copy_(th.as_tensor(x.std(0) + 1e-3))
        self.y_mean.copy_(th.as_tensor(y.mean(0)))
        self.y_std.copy_(th.as_tensor(y.std(0) + 1e-3))
        xn = (th.as_tensor(x) - self.x_mean) / self.x_std
        yn = (th.as_tensor(y) - self.y_mean) / self.y_std
        n, e, bs = len(xn), self.settings.members, self.settings.batch_size
        boot = th.randint(0, n, (e, n), generator=self._gen)
        opt = th.optim.Adam(self.parameters(), lr=self.settings.learning_rate, weight_decay=1e-5)
        loss_sum = 0.0
        for _ in range(epochs):
            order = boot[:, th.randperm(n, generator=self._gen)]
            loss_sum, batches = 0.0, 0
            for start in range(0, n, bs):
                idx = order[:, start : start + bs]
                loss = ((self(xn[idx]) - yn[idx]) ** 2).mean()
                opt.zero_grad()
                loss.backward()
                opt.step()
                loss_sum, batches = loss_sum + loss.item(), batches + 1
            loss_sum /= max(batches, 1)
        self.fitted_rows = n
        return loss_sum

    # -- how good it is -------------------------------------------------------------------------
    @th.no_grad()
    def errors(self, data: Transitions, rows: np.ndarray, horizon: int) -> dict[str, float]:
        """RMSE of the ensemble's mean, one step and `horizon` steps ahead (rolled out along the recorded actions and
        exogenous inputs), against persistence (the state stays as it is), per state element, on `rows`."""
        out: dict[str, float] = {}
        names = self.layout.state_names
        for h in sorted({1, horizon}):
            runs = data.sequences(rows, h)
            if not len(runs):
                continue
            s0 = th.as_tensor(data.array("s")[runs[:, 0]])
            s = s0.expand(self.settings.members, -1, -1)
            for k in range(h):
                s = self.step(s, *(th.as_tensor(data.array(f)[runs[:, k]]) for f in ("a_prev", "a", "x")))
            truth = data.array("s_next")[runs[:, -1]]
            model = ((s.mean(0).numpy() - truth) ** 2).mean(0) ** 0.5
            still = ((s0.numpy() - truth) ** 2).mean(0) ** 0.5
            for i, name in enumerate(names):
                out[f"{name}/{h}_step_model"] = float(model[i])
                out[f"{name}/{h}_step_persistence"] = float(still[i])
            out[f"rows/{h}_step"] = float(len(runs))
        return out

    def arrays(self) -> EnsembleArrays:
        """The weights and normalizers as numbers, for the planner's graph (ensemble_graph.py)."""

        def numpy(t: th.Tensor) -> np.ndarray:
            return t.detach().cpu().numpy().astype(np.float32).copy()

        return EnsembleArrays([numpy(w) for w in self.weights], [numpy(b) for b in self.biases],
                              *(numpy(getattr(self, n)) for n in ("x_mean", "x_std", "y_mean", "y_std")))  # fmt: skip

    # -- saving ---------------------------------------------------------------------------------
    def state(self) -> dict:
        return {"layout": asdict(self.layout), "settings": asdict(self.settings), "weights": self.state_dict(),
                "fitted_rows": self.fitted_rows}  # fmt: skip

    @classmethod
    def from_state(cls, state: dict) -> Ensemble:
        layout = Layout(**{k: tuple(v) if isinstance(v, list) else v for k, v in state["layout"].items()})
        model = cls(layout, MPCSettings.of_saved(state["settings"], "a planner checkpoint"))
        model.load_state_dict(state["weights"])
        model.fitted_rows = state.get("fitted_rows", 0)
        return model


def summary(errors: dict, names, horizon: int) -> str:
    """One log line: each state element's held-out error, 1 and `horizon` steps ahead, beside persistence."""
    parts = []
    for name in names:
        for h in sorted({1, horizon}):
            m, p = errors.get(f"{name}/{h}_step_model"), errors.get(f"{name}/{h}_step_persistence")
            if m is not None:
                parts.append(f"{name} {h}-step {m:.3g} (persistence {p:.3g})")
    return "; ".join(parts) or "(no held-out rows yet)"
