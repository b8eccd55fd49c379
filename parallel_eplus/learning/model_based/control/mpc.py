"""Model predictive control as the service runs it: observations and infos in, every worker's action out.

`MPC` binds the ensemble and the planner to a building: it reads the state from the observations, the future
exogenous inputs from each worker's weather forecast and the clock (exogenous.py: the weather file, or it with
BOPTEST's forecast errors), and when the band applies from `ComfortTimes`. Training steps every worker through it
in one batched plan; `evaluate` runs a saved planner (`planner.pt`: the ensemble's weights and normalizers, the
planner's settings, the comfort weight and the comfort calendar) one episode at a time (saved_planner.py);
deploy/export/planner.py writes one for `serve`.
"""

from __future__ import annotations

import datetime as dt
import logging
from dataclasses import asdict
from pathlib import Path

import numpy as np
import torch as th

from parallel_eplus import io
from parallel_eplus.buildings.building import load_building
from parallel_eplus.buildings.scaling import to_unit
from parallel_eplus.learning.model_based.model.dynamics import Ensemble
from parallel_eplus.learning.model_based.model.exogenous import Forecasts
from parallel_eplus.learning.model_based.runtime.calendar import THERMOSTAT, ComfortTimes, own_reference
from parallel_eplus.learning.model_based.runtime.demand import DemandCharges, DemandWatch
from parallel_eplus.learning.model_based.runtime.energy_weights import EnergyWeights
from parallel_eplus.learning.model_based.runtime.ensemble_graph import OnnxEnsemble, build_graph
from parallel_eplus.learning.model_based.runtime.features import EXOGENOUS, step_times, with_occupancy
from parallel_eplus.learning.model_based.runtime.guard import Guard
from parallel_eplus.learning.model_based.runtime.layout import Layout
from parallel_eplus.learning.model_based.runtime.planner import (
    Plan,
    Planner,
    PlannerSettings,
    PlanRequest,
    decision_seed,
    side_array,
)
from parallel_eplus.learning.model_based.settings import MPCSettings

PLANNER_FILE = "planner.pt"
log = logging.getLogger(__name__)


class MPC:
    """The model, the planner and what they need to know about a building; `act` plans for every worker at once."""

    def __init__(self, building: str | None, settings: MPCSettings, margin_c: float, power_weight: float,
                 workers: int, seed: int = 0, model: Ensemble | None = None, objective: str | None = None):  # fmt: skip
        self.building = building
        b = load_building(building)
        self.step_minutes = 60 * 24 / b.steps_per_day
        self.forecasts = Forecasts(building)
        width = self.forecasts(next(iter(b.spec.weathers), "CA")).width + settings.occupancy_input
        self.layout = model.layout if model is not None else Layout.of(b, width)  # a saved model keeps its own
        self.settings = settings
        self.model = model or Ensemble(self.layout, settings, seed)
        self.comfort_times = ComfortTimes(building, self.step_minutes, settings.comfort_hours == "occupied")
        self.energy_weights = EnergyWeights.of_building(self.layout, b, objective)  # the run's objective's
        kpis = b.comfort.kpis
        charges = None if kpis is None else DemandCharges.of(
            self.layout, b.comfort.power, self.energy_weights.objective, kpis.tariffs.get("Electricity"),
            kpis.demand_w(1.0, self.step_minutes), self.step_minutes)  # fmt: skip
        self.power = b.comfort.power
        self.demand = charges and DemandWatch(charges, self.layout.sensors.index(self.power), workers)
        self.margin_c, self.power_weight = margin_c, power_weight
        self.seed = seed
        self.planner = Planner(None, settings.members, len(self.layout.temperatures), PlannerSettings.of(settings),
                               margin_c, power_weight)  # fmt: skip
        self.refresh()
        self.comfort_weight = 10.0
        n_actions = self.layout.n_actions
        self.support = (-np.ones(n_actions, np.float32), np.ones(n_actions, np.float32))  # `set_support`
        self.warm = np.zeros((workers, settings.horizon, n_actions), np.float32)
        self.last: Plan | None = None
        self.guard: Guard | None = None  # `guard_k`'s, made at the first plan (an evaluation's settings may add it)
        self.action_low = np.array([a.low for a in b.actions], float)  # as the served planner reads them
        self.action_high = np.array([a.high for a in b.actions], float)
        self.initial = to_unit([a.initial for a in b.actions], self.action_low, self.action_high).astype(np.float32)
        self.thermostat_sides = thermostat_sides(b)
        self.sides = side_array(self.thermostat_sides)  # as the planner reads them (`band_thermostats`)
        self.rules: list = [None] * workers  # `baseline_source=rule`: each worker's rule, made at its first plan
        self.ruled = np.zeros(n_actions, bool)  # the actions the rule has set (not released)
        self.check_reference()

    def check_reference(self) -> None:
        """`comfort_reference=baseline` needs the own thermostats' schedules as bounds (`band = "thermostat"`) and an
        action setting one; `comfort_hours=occupied` on a planner saved before the calendar kept occupied hours by
        date falls back on the weekly majority (daylight-saving time and holidays blurred): said, not refused."""
        thermostat = self.comfort_times.mode == THERMOSTAT
        if self.settings.comfort_reference == "baseline" and not (thermostat and any(self.thermostat_sides)):
            raise ValueError(
                f"comfort_reference=baseline: {self.building or 'the building'} has no thermostat action "
                "(a zone's heating or cooling setpoint) that follows a schedule its comfort bounds "
                'read (`band = "thermostat"`)'
            )
        s = self.settings
        if (s.consensus or s.min_saving or s.baseline_radius is not None or s.guard_k is not None
                or s.baseline_margin or s.band_thermostats != "free" or s.baseline_source != "building") and \
                s.comfort_reference != "baseline":  # fmt: skip
            raise ValueError(
                "--mpc consensus, min_saving, baseline_radius, guard_k, baseline_margin, band_thermostats "
                "and baseline_source weigh the search's plan against the baseline: add "
                "comfort_reference=baseline"
            )
        if s.baseline_source == "rule":
            try:
                rule = load_building(self.building).controller_class()
            except ValueError as e:
                raise ValueError(f"baseline_source=rule: {e}") from None
            if not getattr(rule, "relinquishes", False):
                raise ValueError(
                    f"baseline_source=rule: {rule.__name__} must release (NaN) the actions it does not "
                    "set, as parallel_eplus.buildings.rules.air_reset:SupplyAirReset does "
                    "(`relinquishes = True`)"
                )
            try:
                self.rule(0)  # made with the spec's controller_settings: a wrong one fails before any episode
            except ValueError as e:
                raise ValueError(f"baseline_source=rule: {e}") from None
        dated = self.comfort_times.dated_applies
        if self.comfort_times.occupied_only and thermostat and not (dated >= 0).any() and self.comfort_times.seen.any():
            log.warning(
                "comfort_hours=occupied: this planner's calendar has no occupied hours by date (saved before "
                "they were kept); it uses the weekly majority, which blurs daylight-saving time and holidays"
            )

    @property
    def follows(self) -> np.ndarray:
        """[A]: the actions the baseline sets (`baseline_radius`): the thermostats, those whose own setpoints the
        calendar recorded by date, and those the rule has set (`baseline_source=rule`)."""
        sides = np.array([side is not None for side in self.thermostat_sides])
        return sides | self.comfort_times.own_known(len(sides)) | self.ruled

    def own_jump(self) -> float:
        """The largest step, in normalized units, of the own thermostats' plan over the dates the calendar
        recorded (0: none recorded, or no thermostat action). Beyond `max_increment`, no candidate reaches the
        occupied setpoint at the step the schedule does, and neither does the own plan a candidate is measured
        against: that step's discomfort is free (the restaurants' mornings, docs/model-based.md)."""
        c = self.comfort_times
        known = c.dated_weekday >= 0
        if not any(self.thermostat_sides) or not known.any():
            return 0.0
        widened = c.dated + np.array([-c.tolerance, c.tolerance], np.float32)
        ref = own_reference(widened, c.tolerance, self.thermostat_sides, self.action_low, self.action_high,
                            np.zeros(len(self.action_low), np.float32))  # fmt: skip
        steps = np.abs(np.diff(ref, axis=0))[known[1:] & known[:-1]]
        return float(steps.max()) if len(steps) else 0.0

    def exogenous(self, rows: np.ndarray, times: list[dt.datetime]) -> np.ndarray:
        """The model's exogenous inputs at `times` from a forecast's (or the weather's) `rows` [T, X]: with
        `occupancy_input`, whether the building is occupied then (the calendar's, as the served planner reads it)."""
        if not self.settings.occupancy_input:
            return rows
        return with_occupancy(rows, self.comfort_times.occupied(times))

    def exogenous_seen(self, forecast, times: list[dt.datetime]) -> np.ndarray:
        """The model's exogenous inputs at `times` as they happened (its data: `forecast.at`, exogenous.py)."""
        return self.exogenous(forecast.at(times), times)

    @property
    def exogenous_names(self) -> list[str]:
        """The model's exogenous inputs by name, in order (the export's fallback names them)."""
        occupancy = int(self.settings.occupancy_input)
        schedule = self.layout.n_exogenous - len(EXOGENOUS) - occupancy  # the IT load's (the data centers)
        return list(EXOGENOUS[: self.layout.n_exogenous]) + ["it_load"] * schedule + ["occupied"] * occupancy

    def refresh(self) -> None:
        """The planner's forward from the model's current weights (after every fit)."""
        self.planner.forward = OnnxEnsemble(build_graph(self.model.arrays()))

    def set_support(self, actions: np.ndarray) -> None:
        """Keep the actions within the range of each action in the data widened by `support_margin`: it can only
        grow (the data only grow), by up to the margin at each refit where the planner's own steps reach its edge."""
        if len(actions):
            m = self.settings.support_margin
            lo, hi = actions.min(axis=0), actions.max(axis=0)
            self.support = (np.maximum(lo - m, -1.0).astype(np.float32), np.minimum(hi + m, 1.0).astype(np.float32))

    def reset(self, worker: int) -> None:
        """A new episode for `worker`: forget its warm start and its demand peaks."""
        self.warm[worker] = 0.0
        self.rules[worker] = None  # its rule's state (a reset's trim and respond) starts again
        if self.guard:
            self.guard.reset(worker)
        if self.demand:
            self.demand.reset(worker)

    def future(self, infos: list[dict]) -> tuple[np.ndarray, ...]:
        """(exogenous inputs [W, H, X], whether the band applies [W, H], each zone's bounds [W, H, K, 2], the
        energy parts' weights [W, H, P] or None where each counts once) over each worker's horizon."""
        exo, applies, bounds, weights = [], [], [], []
        for info in infos:
            times = step_times(info["time"], self.step_minutes, self.settings.horizon)
            exo.append(self.exogenous(self.forecasts.of(info).ahead(info["time"], times), times))
            applies.append(self.comfort_times(times))
            bounds.append(self.comfort_times.bounds(times))
            if self.energy_weights.objective != "energy":  # priced when each step begins; energy: each part once
                weights.append(self.energy_weights.at([info["time"], *times[:-1]]))
        return np.stack(exo), np.stack(applies), np.stack(bounds), np.stack(weights) if weights else None

    def act(self, obs: np.ndarray, infos: list[dict], a_last: np.ndarray) -> np.ndarray:
        """Every worker's next normalized action from its observation (sensors first) and info (time, weather)."""
        exo, applies, bounds, weights = self.future(infos)
        s = self.layout.state(np.asarray(obs)[:, : len(self.layout.sensors)])
        a_last = np.asarray(a_last, np.float32)
        demand = self.demand.outlook(obs, infos, self.settings.horizon) if self.demand else None
        seeds = [decision_seed(self.seed, info["time"].isoformat(), s[i]) for i, info in enumerate(infos)]
        reference = (
            self.baseline_plan(infos, bounds, a_last, obs) if self.settings.comfort_reference == "baseline" else None
        )
        hold = self._guard_check(s, infos) if reference is not None else None
        self.last = self.planner.plan(PlanRequest(
            s, a_last, exo, applies, bounds, self.comfort_weight, self.support, self.warm[: len(s)], seeds,
            energy_weights=weights, reference=reference, demand=demand, follows=self.follows, hold=hold,
            sides=self.sides))  # fmt: skip
        self.warm[: len(s)] = self.last.increments
        if hold is not None:
            self.guard.record(self.last, bounds[:, 0], applies[:, 0])
        return self.last.action

    def _guard_check(self, s: np.ndarray, infos: list[dict]) -> np.ndarray | None:
        """[W]: the workers `guard_k`'s guard has play the own plan (None: no guard), from the zones' discomfort
        observed at the end of the step just taken."""
        c = self.settings
        if c.guard_k is None:
            return None
        if self.guard is None or (self.guard.k, self.guard.steps) != (c.guard_k, c.guard_steps):
            self.guard = Guard(len(self.warm), c.guard_k, c.guard_steps, self.comfort_times.tolerance)
        now = [info["time"] for info in infos]  # one time per worker
        return self.guard.check(s[:, : self.planner.n_temps], self.comfort_times.bounds(now), self.comfort_times(now))

    def baseline_plan(self, infos: list[dict], bounds: np.ndarray, a_last: np.ndarray,
                 obs: np.ndarray | None = None) -> np.ndarray:  # fmt: skip
        """[W, H, A]: what the building's own controls would set over each worker's horizon (`own_reference`), from
        `future`'s bounds and the own setpoints the calendar recorded on those dates; with `baseline_source=rule`, the
        actions the rule sets at its value now, held over the horizon (a rule is called once a step: its state)."""
        c, h = self.comfort_times, self.settings.horizon
        inside = c.tolerance + self.settings.baseline_margin  # the bounds were widened by the tolerance
        plan = np.stack([own_reference(bounds[i], inside, self.thermostat_sides, self.action_low, self.action_high,
                                       a_last[i], c.own_actions(step_times(info["time"], self.step_minutes, h)))
                         for i, info in enumerate(infos)])  # fmt: skip
        if self.settings.baseline_source == "rule":
            not_thermostat = np.array([side is None for side in self.thermostat_sides])
            n = len(self.layout.sensors)
            for i, info in enumerate(infos):  # the sensors as observed (float32, clipped): what a served rule reads
                seen = info | dict(zip(self.layout.sensors, np.asarray(obs)[i][:n].tolist(), strict=True))
                ruled = self.rule(i)(np.asarray(obs)[i], seen)
                sets = np.isfinite(ruled) & not_thermostat
                plan[i][:, sets] = ruled[sets]
                self.ruled |= sets
        return plan

    def rule(self, worker: int):
        """The worker's rule (the spec's `controller`, as `evaluate --rbc` makes it), fresh after its reset."""
        if self.rules[worker] is None:
            from parallel_eplus.evaluation.controllers import RBC_LABEL, Controller

            self.rules[worker] = Controller(RBC_LABEL, "rbc").make(self.building)
        return self.rules[worker]

    def observe(self, obs: np.ndarray, infos: list[dict]) -> None:
        """Each worker's meter reading of the step that just ended, for its month's demand peaks (`act` reads it
        too; the training loop gives it while it explores)."""
        if self.demand:
            self.demand.observe(obs, infos)

    # -- saving: a planner checkpoint -----------------------------------------------------------
    def state(self) -> dict:
        return {
            "building": self.building, "ensemble": self.model.state(), "settings": asdict(self.settings),
            "margin_c": self.margin_c, "power_weight": self.power_weight, "comfort_weight": self.comfort_weight,
            "objective": self.energy_weights.objective,
            "support_low": th.as_tensor(self.support[0]), "support_high": th.as_tensor(self.support[1]),
            **{k: th.as_tensor(v) for k, v in self.comfort_times.state().items()},
        }  # fmt: skip

    def save(self, path: Path) -> Path:
        path.parent.mkdir(parents=True, exist_ok=True)
        with io.atomic_path(path) as tmp:
            th.save(self.state(), tmp)
        return path

    @classmethod
    def from_state(cls, state: dict, workers: int = 1, seed: int = 0) -> MPC:
        settings = MPCSettings.of_saved(state["settings"], "a planner checkpoint")
        model = Ensemble.from_state(state["ensemble"])
        mpc = cls(
            state["building"],
            settings,
            state["margin_c"],
            state["power_weight"],
            workers,
            seed,
            model,
            state.get("objective", "energy"),
        )  # planners saved before objectives: energy
        mpc.comfort_weight = float(state["comfort_weight"])
        mpc.support = tuple(np.asarray(state[k], np.float32) for k in ("support_low", "support_high"))
        mpc.comfort_times.load(state)
        mpc.check_reference()
        return mpc

    @classmethod
    def load(cls, path: Path, workers: int = 1, seed: int = 0) -> MPC:
        state = th.load(path, weights_only=True)  # tensors, numbers, strings: a shared planner cannot run code
        return cls.from_state(state, workers, seed)


def thermostat_sides(building) -> list[tuple[int, int] | None]:
    """Per action, a comfort zone whose bound is the schedule the action's own thermostat setpoint follows, and
    which bound (0 lower, 1 upper): `Building.own` against `Building.zone_bounds`. None where its actuators follow
    no such schedule, or not all the same one (a supply-air node, a fan)."""
    bounds = building.zone_bounds or ()
    sides: list[tuple[int, int] | None] = []
    for schedules in building.own or [() for _ in building.actions]:
        found = [(k, e) for k, pair in enumerate(bounds) for e in (0, 1) if schedules and pair[e] == schedules[0]]
        sides.append(found[0] if found and len(set(schedules)) == 1 else None)
    return sides
