"""Model predictive control as the service runs it: observations and infos in, every worker's action out.

`MPC` binds the ensemble and the planner to a building: it reads the state from the observations, the future
exogenous inputs from each worker's weather file and the clock (exogenous.py: a perfect weather forecast), and
when the band applies from `ComfortTimes`. Training steps every worker through it in one batched plan; `evaluate`
runs a saved planner (`planner.pt`: the ensemble's weights and normalizers, the planner's settings, the comfort
weight and the comfort calendar) one episode at a time (`PlannerActor`).
"""

from __future__ import annotations

import datetime as dt
from dataclasses import asdict
from pathlib import Path

import numpy as np
import torch as th

from parallel_eplus import io
from parallel_eplus.buildings.building import load_building
from parallel_eplus.learning.model_based.dataset import ComfortTimes, Layout
from parallel_eplus.learning.model_based.dynamics import Ensemble
from parallel_eplus.learning.model_based.exogenous import Forecasts
from parallel_eplus.learning.model_based.planner import Planner
from parallel_eplus.learning.model_based.settings import MPCSettings

PLANNER_FILE = "planner.pt"


class MPC:
    """The model, the planner and what they need to know about a building; `act` plans for every worker at once."""

    def __init__(self, building: str | None, settings: MPCSettings, margin_c: float, power_weight: float,
                 workers: int, seed: int = 0, model: Ensemble | None = None):  # fmt: skip
        self.building = building
        b = load_building(building)
        self.step_minutes = 60 * 24 / b.steps_per_day
        self.forecasts = Forecasts(building)
        width = self.forecasts(next(iter(b.spec.weathers), "CA")).width
        self.layout = model.layout if model is not None else Layout.of(b, width)  # a saved model keeps its own
        self.settings = settings
        self.model = model or Ensemble(self.layout, settings, seed)
        self.comfort_times = ComfortTimes(building, self.step_minutes)
        self.margin_c, self.power_weight = margin_c, power_weight
        self.planner = Planner(self.model, settings, margin_c, power_weight, workers, seed)
        self.comfort_weight = 10.0
        self.initial = np.array([2 * (a.initial - a.low) / (a.high - a.low) - 1 for a in b.actions], np.float32)

    def future(self, infos: list[dict]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(exogenous inputs [W, H, X], whether the band applies [W, H], each zone's bounds [W, H, K, 2]) over each
        worker's horizon."""
        exo, applies, bounds = [], [], []
        for info in infos:
            t = info["time"]
            times = [t + dt.timedelta(minutes=self.step_minutes * (h + 1)) for h in range(self.settings.horizon)]
            exo.append(self.forecasts.of(info).at(times))
            applies.append(self.comfort_times(times))
            bounds.append(self.comfort_times.bounds(times))
        return np.stack(exo), np.stack(applies), np.stack(bounds)

    def act(self, obs: np.ndarray, infos: list[dict], a_last: np.ndarray) -> np.ndarray:
        """Every worker's next normalized action from its observation (sensors first) and info (time, weather)."""
        exo, applies, bounds = self.future(infos)
        s = self.layout.state(np.asarray(obs)[:, : len(self.layout.sensors)])
        return self.planner.plan(s, a_last, exo, applies, bounds, self.comfort_weight)

    # -- saving: a planner checkpoint -----------------------------------------------------------
    def state(self) -> dict:
        return {
            "building": self.building, "ensemble": self.model.state(), "settings": asdict(self.settings),
            "margin_c": self.margin_c, "power_weight": self.power_weight, "comfort_weight": self.comfort_weight,
            "support_low": self.planner.support[0], "support_high": self.planner.support[1],
            **{k: th.as_tensor(v) for k, v in self.comfort_times.state().items()},
        }  # fmt: skip

    def save(self, path: Path) -> Path:
        path.parent.mkdir(parents=True, exist_ok=True)
        with io.atomic_path(path) as tmp:
            th.save(self.state(), tmp)
        return path

    @classmethod
    def from_state(cls, state: dict, workers: int = 1, seed: int = 0) -> MPC:
        settings = MPCSettings(**state["settings"])
        model = Ensemble.from_state(state["ensemble"])
        mpc = cls(state["building"], settings, state["margin_c"], state["power_weight"], workers, seed, model)
        mpc.comfort_weight = state["comfort_weight"]
        mpc.planner.support = (state["support_low"], state["support_high"])
        mpc.comfort_times.load(state)
        return mpc

    @classmethod
    def load(cls, path: Path, workers: int = 1, seed: int = 0) -> MPC:
        state = th.load(path, weights_only=True)  # tensors, numbers, strings: a shared planner cannot run code
        return cls.from_state(state, workers, seed)


def planner_controller(spec: str):
    """`evaluate --policy runs/<name>/planner[=LABEL]` (or a planner.pt): the planner as an evaluation
    controller; None when `spec` names anything else (a policy)."""
    import functools
    import json

    from parallel_eplus.evaluation.controllers import Controller

    path_text, _, label = spec.partition("=")
    path = Path(path_text)
    if path.name != "planner" and path.suffix != ".pt":
        return None
    found = planner_file(path)
    if found is None:
        raise FileNotFoundError(
            f"{path}: no {PLANNER_FILE} (a `train --algorithm mpc` run writes runs/<name>/planner/)"
        )
    config = found.parent / "config.json"
    saved = json.loads(config.read_text()) if config.is_file() else {}
    building = saved.get("building")
    if building and (not Path(building).is_file() or Path(building).parent.match("parallel_eplus/buildings/specs")):
        building = Path(building).stem  # a built-in spec, saved by path by another checkout or install
    label = label or f"MPC planner ({'-'.join(saved.get('weathers', []))})"
    run = saved.get("run_name") or found.parent.parent.name
    return Controller(label, "planner", found, building=building, run=run,
                      factory=functools.partial(PlannerActor, found))  # fmt: skip


def planner_file(path: str | Path) -> Path | None:
    """The planner a path names (a planner.pt, a folder with one, or a run folder with planner/), or None."""
    path = Path(path)
    for candidate in (path, path / PLANNER_FILE, path / "planner" / PLANNER_FILE):
        if candidate.name == PLANNER_FILE and candidate.is_file():
            return candidate
    return None


class PlannerActor:
    """A saved planner as an evaluation controller: (observation, info) -> normalized action, one episode."""

    def __init__(self, path: Path):
        th.set_num_threads(1)  # the cores belong to EnergyPlus (as in training); more threads only contend
        self.mpc = MPC.load(path)
        self.last = self.mpc.initial.copy()

    def __call__(self, obs: np.ndarray, info: dict) -> np.ndarray:
        self.last = self.mpc.act(obs[None, :], [info], self.last[None, :])[0]
        return self.last
