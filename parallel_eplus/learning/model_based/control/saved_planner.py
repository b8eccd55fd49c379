"""A saved planner (`planner.pt`), found from what a user names and run as an evaluation controller.

`evaluate --policy runs/<name>/planner` and `evaluate --planner OPTIONS` come here; `export` finds the planner a run
chose (`planner_source`). The planner itself: control.py.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch as th

from parallel_eplus.buildings.resources import saved_building
from parallel_eplus.buildings.weather.forecast import FORECASTS
from parallel_eplus.learning.model_based.control.mpc import MPC, PLANNER_FILE
from parallel_eplus.learning.model_based.model.exogenous import Forecasts
from parallel_eplus.learning.model_based.runtime.planner import PlannerSettings
from parallel_eplus.learning.model_based.settings import MPCSettings


def planner_controller(spec: str, options: str | None = None):
    """`evaluate --policy runs/<name>/planner[=LABEL]` (or a planner.pt): the planner as an evaluation
    controller; None when `spec` names anything else (a policy). `options` (`evaluate --planner`): its forecast
    and settings for this evaluation (`PlannerOptions`)."""
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
    building = saved_building(saved)
    label = label or f"MPC planner ({'-'.join(saved.get('weathers', []))})"
    run = saved.get("run_name") or found.parent.parent.name
    PlannerOptions.parse(options)  # refused here, before any episode
    return Controller(label, "planner", found, building=building, run=run,
                      factory=functools.partial(PlannerActor, found, options))  # fmt: skip


def planner_file(path: str | Path) -> Path | None:
    """The planner a path names (a planner.pt, a folder with one, or a run folder with planner/), or None."""
    path = Path(path)
    for candidate in (path, path / PLANNER_FILE, path / "planner" / PLANNER_FILE):
        if candidate.name == PLANNER_FILE and candidate.is_file():
            return candidate
    return None


@dataclass(frozen=True)
class PlannerOptions:
    """How a saved planner runs in an evaluation: its forecast (`FORECASTS`: the weather file, or it with BOPTEST's
    low, medium or high errors), its sampler's seed, and settings overriding its own (`MPCSettings` fields:
    candidates, iterations, ...)."""

    forecast: str = "perfect"
    settings: str = ""
    seed: int | None = None  # None: the planner's own
    flag: str = "--planner"  # the option they came from, named in errors

    @classmethod
    def parse(cls, text: str | None, flag: str = "--planner") -> PlannerOptions:
        """`"forecast=medium,seed=1,candidates=128"`: `forecast`, `seed` and any of MPCSettings' fields; `flag`: the
        option that gave them (`evaluate --planner`, `export --planner-options`), named in errors."""
        forecast, seed, rest = "perfect", None, []
        for item in filter(None, (p.strip() for p in (text or "").split(","))):
            key, _, value = item.partition("=")
            if key.strip() == "forecast":
                forecast = value.strip()
                if forecast not in FORECASTS:
                    raise ValueError(f"{flag} forecast={forecast!r}: one of {', '.join(FORECASTS)}")
            elif key.strip() == "seed":
                try:
                    seed = int(value)
                except ValueError:
                    raise ValueError(f"{flag} seed={value.strip()!r}: a whole number") from None
            else:
                rest.append(item)
        MPCSettings.from_text(",".join(rest), flag=flag)  # refused by name here
        return cls(forecast, ",".join(rest), seed, flag)

    def apply(self, mpc: MPC) -> MPC:
        if self.settings:
            settings = MPCSettings.from_text(self.settings, mpc.settings, flag=self.flag)
            if settings.occupancy_input != mpc.settings.occupancy_input:
                raise ValueError(f"--planner occupancy_input: the model was trained with occupancy_input="
                                 f"{str(mpc.settings.occupancy_input).lower()} (one of its inputs); a saved planner "
                                 "keeps it")  # fmt: skip
            mpc.settings, mpc.planner.settings = settings, PlannerSettings.of(settings)
            mpc.warm = np.zeros((len(mpc.warm), mpc.settings.horizon, mpc.layout.n_actions), np.float32)
            if mpc.settings.comfort_weight is not None:  # the weight the planner plans with, not only its setting
                mpc.comfort_weight = mpc.settings.comfort_weight
            mpc.comfort_times.occupied_only = mpc.settings.comfort_hours == "occupied"
            mpc.check_reference()
        if self.seed is not None:
            mpc.seed = self.seed
        if self.forecast != "perfect":
            mpc.forecasts = Forecasts(mpc.building, self.forecast, mpc.seed)
        return mpc


def planner_source(path: Path) -> Path | None:
    """The planner.pt a path names: a planner file or folder, or a model-based run (its `best/planner`, the one
    `--eval-every` chose, else its final `planner`); None for anything else."""
    path = Path(path)
    if path.is_dir() and (path / "best" / "planner" / PLANNER_FILE).is_file():
        return path / "best" / "planner" / PLANNER_FILE
    return planner_file(path)


class PlannerActor:
    """A saved planner as an evaluation controller: (observation, info) -> normalized action, one episode."""

    def __init__(self, path: Path, options: str | None = None):
        th.set_num_threads(1)  # the cores belong to EnergyPlus (as in training); more threads only contend
        self.mpc = PlannerOptions.parse(options).apply(MPC.load(path))
        self.last = self.mpc.initial.copy()

    def __call__(self, obs: np.ndarray, info: dict) -> np.ndarray:
        self.last = self.mpc.act(obs[None, :], [info], self.last[None, :])[0]
        return self.last
