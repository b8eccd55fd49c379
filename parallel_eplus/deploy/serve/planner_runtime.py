"""An exported planner answering one request: readings, the last setpoints and a forecast in; setpoints out.

Numpy and onnxruntime only (the `serve` extra): the ensemble is ensemble.onnx, the rest is arrays in planner.npz
and numbers in controller.json (planner_export.py writes them). The server holds no state between requests: what
the planner needs from the last step comes in the request (the last setpoints; optionally the rest of the last
plan, `plan`, which the answer returns for the next request to warm-start from), and the sampler is seeded from the
request, so the same request gets the same answer, and a served episode equals the in-process one.

It knows when not to be trusted (`fallback`): when a reading lies far outside the data the model learned from,
when the forecast contradicts the outdoor sensor, when the ensemble's members disagree about a zone's temperature
at the end of the coming step (the setpoints held) by more than the contract's threshold (`max_step_spread_k`,
calibrated at export on the building's own record: what the model has not seen, its members disagree on), or
about a zone's temperature along the plan by more than `max_spread_k`. The answer then carries `"fallback": true`,
the reason, and the setpoints the building's own controls set at that date and time (recorded at export over a
year, own_setpoints.py); a building-management system should hand control back to its own loops (docs/deploy.md).
"""

from __future__ import annotations

import logging
import math
from pathlib import Path

import numpy as np

from parallel_eplus.buildings.scaling import from_unit, to_unit
from parallel_eplus.buildings.weather.forecast import WEATHER
from parallel_eplus.deploy.serve.contract import Contract, InputError, verified_file
from parallel_eplus.deploy.serve.own_setpoints import OwnSetpoints
from parallel_eplus.learning.model_based.runtime.calendar import Calendar, own_reference
from parallel_eplus.learning.model_based.runtime.demand import DemandCharges, DemandOutlook
from parallel_eplus.learning.model_based.runtime.energy_weights import EnergyWeights
from parallel_eplus.learning.model_based.runtime.ensemble_graph import OnnxEnsemble
from parallel_eplus.learning.model_based.runtime.features import WEATHER_SCALE, exogenous, step_times, with_occupancy
from parallel_eplus.learning.model_based.runtime.guard import Guard, GuardState
from parallel_eplus.learning.model_based.runtime.layout import Layout
from parallel_eplus.learning.model_based.runtime.planner import (
    Planner,
    PlannerSettings,
    PlanRequest,
    decision_seed,
    side_array,
)
from parallel_eplus.learning.model_based.runtime.renamed import renamed

log = logging.getLogger("parallel_eplus.deploy.planner")

PLANNER_ARRAYS = "planner.npz"
ENSEMBLE_FILE = "ensemble.onnx"
ROLLOUT_FILE = "rollout.onnx"  # the ensemble over the planner's horizon in one call (a contract before it has none)
# What the weather can be anywhere on Earth: a forecast value outside is refused, naming it (the records: -89.2 °C,
# 56.7 °C; the sun gives at most ~1361 W/m2 above the atmosphere, a little more on the ground under broken clouds).
FORECAST_LIMITS = {"outdoor_drybulb_c": (-90.0, 60.0), "outdoor_rh_pct": (0.0, 100.0),
                   "global_horizontal_w_m2": (0.0, 1500.0)}  # fmt: skip
DEFAULT_FORECAST_GAP_C = 6.0  # a forecast's dry bulb jumping more than this between two steps: fallback


class PlannerRuntime:
    """One exported planner (`directory`: what `export` wrote), answering `act(body)`."""

    def __init__(self, directory: Path, contract: Contract):
        self.contract, p = contract, contract.data["planner"]
        arrays = dict(np.load(Path(directory) / PLANNER_ARRAYS))
        self.layout = Layout(**{k: tuple(v) if isinstance(v, list) else v for k, v in p["layout"].items()})
        self.settings = PlannerSettings.of(p["settings"])  # a field an older contract lacks: its default
        rollout = contract.data["onnx"].get("rollout")
        rollouts = None if not rollout else {(rollout["horizon"], rollout["n_temps"]): verified_file(
            directory, rollout, "rollout graph").read_bytes()}  # fmt: skip
        forward = OnnxEnsemble((Path(directory) / contract.data["onnx"]["file"]).read_bytes(), rollouts)
        self.planner = Planner(forward, forward.members, len(self.layout.temperatures), self.settings,
                               p["margin_c"], p["power_weight"])  # fmt: skip
        self.comfort_weight, self.seed, self.step_minutes = p["comfort_weight"], p["seed"], p["step_minutes"]
        self.schedule = tuple(tuple(x) for x in p["schedule"]) if p.get("schedule") else None
        self.support = (arrays["support_low"], arrays["support_high"])
        parts = self.layout.n_state - len(self.layout.temperatures)
        self.energy = EnergyWeights.from_entry(p.get("energy"), parts, Path(directory))  # the objective's prices
        d = p.get("demand")  # the demand charges: contracts written before them, or without any, have none
        self.demand = None if not d else DemandCharges(self.energy.tariffs["Electricity"], self.step_minutes,
                                                       d["part"], d["per_dollar"])  # fmt: skip
        self.calendar = Calendar.from_arrays(p["calendar"], {k: v for k, v in arrays.items() if k in _CALENDAR})
        # "baseline": discomfort beyond the baseline's (the own thermostats' plan) is paid; 1.0's "own" renamed
        self.reference = renamed("comfort_reference", p.get("comfort_reference", "band"), "a contract")[1]
        self.sides = [tuple(x) if x is not None else None for x in p.get("thermostat_sides", [])]
        sides = np.array([side is not None for side in self.sides], bool)  # the baseline sets these
        self.side_array = side_array(self.sides)  # and which bound each thermostat's is (band_thermostats)
        self.follows = sides | self.calendar.own_known(len(sides))
        self.not_thermostat = ~sides
        self.rule = None  # the rule the planner rides (`baseline_source=rule`): its setpoints the baseline's
        if contract.data.get("rule"):
            from parallel_eplus.deploy.serve.served_rule import ServedRule

            self.rule = ServedRule(contract.data["rule"], [s["name"] for s in contract.sensors])
        self.own = OwnSetpoints(arrays, self.step_minutes)  # the building's own setpoints at a date and time
        self.x_mean, self.x_std = arrays["x_mean"], arrays["x_std"]
        self.low = np.array([o["low"] for o in contract.outputs])
        self.high = np.array([o["high"] for o in contract.outputs])
        self.names = [o["name"] for o in contract.outputs]
        self.forecast, self.fallback = contract.data["forecast"], contract.data["fallback"]
        self.outdoor = self.forecast.get("sensor")  # the observed outdoor dry bulb, where the building has one

    # -- one request ----------------------------------------------------------------------------
    def _read(self, body: dict):
        """A request's readings, time, last setpoints (normalized), step times, forecast [H, 3] and its source, the
        model's state [1, S] and exogenous inputs [1, H, X]; refuses what is wrong, naming the field."""
        obs = self.contract.observation(body)[0]  # refuses bad readings and time, naming the field
        when = Contract._time(body.get("time"))
        last = self._last_setpoints(body.get("last_setpoints"))
        a_last = to_unit(last, self.low, self.high).astype(np.float32)
        times = step_times(when, self.step_minutes, self.settings.horizon)
        weather, source = self._forecast(body.get("forecast"), body.get("sensors", {}))
        s = self.layout.state(obs[None, : len(self.layout.sensors)])
        exo = exogenous(weather, times, self.schedule)
        if self.settings.occupancy_input:  # whether the building is occupied then, as the calendar recorded it
            exo = with_occupancy(exo, self.calendar.occupied(times))
        return obs, when, a_last, times, weather, source, s, exo[None]

    def held_spreads(self, bodies: list[dict]) -> np.ndarray:
        """[N]: `step_spread` of each request, without planning (export calibrates `max_step_spread_k` on them)."""
        rows = []
        for body in bodies:
            _, _, a_last, _, _, _, s, exo = self._read(body)
            rows.append(self.held_row(s[0], a_last, exo[0]))
        return self.step_spread(np.stack(rows))

    def act(self, body: dict) -> dict:
        obs, when, a_last, times, weather, source, s, exo = self._read(body)
        warm = self._warm(body.get("plan"))
        seed = decision_seed(self.seed, when.isoformat(), s[0])
        weights = None if self.energy.objective == "energy" else self.energy.at([when, *times[:-1]])[None]
        bounds = self.calendar.bounds(times)
        reference, follows, ruled, rule_state = None, self.follows, None, None
        if self.reference == "baseline":
            inside = self.calendar.tolerance + self.settings.baseline_margin  # as mpc.py's `baseline_plan`
            reference = own_reference(bounds, inside, self.sides, self.low, self.high, a_last,
                                      self.calendar.own_actions(times))[None]  # fmt: skip
        if self.rule is not None:  # its setpoints now, held over the horizon, as mpc.py's `baseline_plan`
            ruled, rule_state = self.rule.step(body, obs)
            ruled[~self.not_thermostat] = np.nan
            sets = np.isfinite(ruled)
            reference[0][:, sets] = ruled[sets]
            follows = follows | sets
        demand = None
        if self.demand is not None:  # the month's running peaks come with the request (the server keeps no state)
            try:
                peaks = self.demand.peaks_of(body.get("demand_peaks_kw"), when)
            except ValueError as e:
                field, _, why = str(e).partition(": ")
                raise InputError(field, why) from None
            prices, running = self.demand.outlook([when, *times[:-1]], peaks)
            demand = DemandOutlook(prices[None], running[None], self.demand.part, self.demand.per_dollar)
        guard = self._guard(body.get("guard"), s, when) if reference is not None else None
        applies = self.calendar(times)[None]
        step_spread = float(self.step_spread(self.held_row(s[0], a_last, exo[0])[None])[0])
        plan = self.planner.plan(PlanRequest(
            s, a_last[None], exo, applies, bounds[None], self.comfort_weight, self.support, warm[None], [seed],
            energy_weights=weights, reference=reference, demand=demand, follows=follows,
            hold=None if guard is None else guard[1], sides=self.side_array))  # fmt: skip
        action = plan.action[0].astype(np.float64)
        answer = {
            "setpoints": self._physical(from_unit(action, self.low, self.high)),
            "time": body.get("time"), "fallback": False, "forecast": source,
            "plan": plan.increments[0].tolist(), "spread_k": round(float(plan.spread_k[0]), 4),
            "cost": round(float(plan.cost[0]), 4), "plan_ms": round(plan.ms, 2),
        }  # fmt: skip
        if rule_state is not None:  # the rule's memory, for the next request to send back (`rule_state`)
            answer["rule_state"] = rule_state
        if guard is not None:  # its state, for the next request to send back (`guard`)
            guard[0].record(plan, bounds[None, 0], applies[:, 0])
            answer["guard"] = guard[0].states[0].as_dict()
        answer["step_spread_k"] = round(step_spread, 4)
        reason = self._distrust(s[0], a_last, exo[0], weather, body.get("sensors", {}), float(plan.spread_k[0]),
                                step_spread)  # fmt: skip
        if reason:
            log.warning("fallback at %s: %s", body.get("time"), reason)
            own = self.own(when)
            if ruled is not None:  # where the rule sets a setpoint, the rule's (the own plan the planner rode)
                sets = np.isfinite(ruled)
                own[sets] = from_unit(ruled, self.low, self.high)[sets]
            answer.update(setpoints=self._physical(own), fallback=True, reason=reason, plan=None)
        return answer

    def _guard(self, given, s: np.ndarray, when) -> tuple[Guard, np.ndarray] | None:
        """`guard_k`'s guard from the request's `guard` (the last answer's), and whether it has this step play the own
        plan: the zones' discomfort now against what the last answer predicted for the own plan (None: no guard)."""
        if self.settings.guard_k is None:
            return None
        try:
            state = GuardState.of(given)
        except ValueError as e:
            raise InputError("guard", str(e)) from None
        guard = Guard(1, self.settings.guard_k, self.settings.guard_steps, self.calendar.tolerance)
        guard.states[0] = state
        return guard, guard.check(s[:, : self.planner.n_temps], self.calendar.bounds([when]), self.calendar([when]))

    def _physical(self, values: np.ndarray) -> dict[str, dict]:
        return self.contract.setpoints(np.clip(values, self.low, self.high))

    def _last_setpoints(self, given) -> np.ndarray:
        if not isinstance(given, dict):
            raise InputError("last_setpoints", f"required: an object of {', '.join(self.names)} (physical units)")
        values = []
        for name, low, high in zip(self.names, self.low, self.high, strict=True):
            v = given.get(name)
            v = v.get("value") if isinstance(v, dict) else v
            if isinstance(v, bool) or not isinstance(v, int | float) or not math.isfinite(v):
                raise InputError(f"last_setpoints.{name}", "missing or not a finite number")
            if not low <= v <= high:
                raise InputError(f"last_setpoints.{name}", f"{v} is outside [{low}, {high}]")
            values.append(float(v))
        return np.array(values)

    def _forecast(self, given, sensors: dict) -> tuple[np.ndarray, str]:
        """[H, 3] physical forecast values at the ends of the coming steps, and where they came from."""
        h = self.settings.horizon
        if given is None:
            if self.forecast.get("missing") != "persistence":
                names = ", ".join(WEATHER)
                raise InputError("forecast", f"required: {{{names}: [{h} values at the end of each coming step]}}")
            now = [self._persisted(i, sensors) for i in range(len(WEATHER))]
            return np.tile(now, (h, 1)), "persistence"
        if not isinstance(given, dict):
            raise InputError("forecast", "must be an object of variable -> list of values")
        unknown = sorted(set(given) - set(WEATHER))
        if unknown:
            raise InputError(f"forecast.{unknown[0]}", f"unknown; the forecast's variables are {', '.join(WEATHER)}")
        columns = []
        for name in WEATHER:
            values = given.get(name)
            if not isinstance(values, list) or len(values) != h:
                got = f"{len(values)} values" if isinstance(values, list) else "none"
                raise InputError(f"forecast.{name}", f"{got}; the contract's horizon is {h} steps: a list of {h} "
                                 "values, one at the end of each coming step (contract `forecast.steps`)")  # fmt: skip
            low, high = FORECAST_LIMITS[name]
            for k, v in enumerate(values):
                if isinstance(v, bool) or not isinstance(v, int | float) or not math.isfinite(v):
                    raise InputError(f"forecast.{name}[{k}]", "every value must be a finite number")
                if not low <= v <= high:
                    raise InputError(f"forecast.{name}[{k}]", f"{v} is outside what the weather can be [{low}, {high}]")
            columns.append(values)
        return np.array(columns, float).T, "given"

    def _persisted(self, i: int, sensors: dict) -> float:
        """Persistence: the outdoor sensor's reading for dry bulb where the building has one; the training data's
        mean for the rest (humidity and sun are not observed)."""
        if i == 0 and self.outdoor:
            reading = sensors.get(self.outdoor)
            return float(reading.get("value") if isinstance(reading, dict) else reading)
        exo_start = self.layout.n_state + 2 * self.layout.n_actions
        return float(self.x_mean[exo_start + i] / WEATHER_SCALE[i])

    def _warm(self, given) -> np.ndarray:
        h, a = self.settings.horizon, self.layout.n_actions
        if given is None:
            return np.zeros((h, a), np.float32)
        warm = np.asarray(given, float) if isinstance(given, list) else None
        if warm is None or warm.shape != (h, a) or not np.all(np.isfinite(warm)):
            raise InputError("plan", f"must be the last answer's plan: {h} lists of {a} numbers")
        return warm.astype(np.float32)  # the search clips every increment it tries

    def held_row(self, s: np.ndarray, a_last: np.ndarray, exo: np.ndarray) -> np.ndarray:
        """The model's input for the coming step with the last setpoints held: what the fallback's checks read."""
        return np.concatenate([s, a_last, a_last, exo[0]]).astype(np.float32)

    def step_spread(self, rows: np.ndarray) -> np.ndarray:
        """[N]: the members' largest disagreement (standard deviation, K) about a zone's temperature at the end of
        the coming step, from held rows [N, inputs] (`held_row`): the model's own measure of what it has not seen."""
        out = self.planner.forward(np.broadcast_to(rows, (self.planner.members, *rows.shape)))
        return out[:, :, : self.planner.n_temps].std(0, ddof=1).max(-1)

    def _distrust(self, s, a_last, exo, weather, sensors: dict, spread_k: float, step_spread: float) -> str | None:
        """Why this answer should not be trusted, or None."""
        f = self.fallback
        row = self.held_row(s, a_last, exo)
        z = np.abs(row - self.x_mean) / self.x_std
        worst = int(np.argmax(z))
        if z[worst] > f["max_input_z"]:
            name, value = self._input_name(worst, row)
            return (f"{name} is {value}{z[worst]:.1f} standard deviations from the data the model learned from "
                    f"(threshold {f['max_input_z']})")  # fmt: skip
        if self.outdoor and f.get("max_forecast_gap_c") is not None:
            reading = sensors.get(self.outdoor)
            reading = float(reading.get("value") if isinstance(reading, dict) else reading)
            gap = abs(float(weather[0, 0]) - reading)
            if gap > f["max_forecast_gap_c"]:
                return (f"the forecast's first dry bulb ({weather[0, 0]:.1f} °C) is {gap:.1f} K from the outdoor "
                        f"sensor (threshold {f['max_forecast_gap_c']} K)")  # fmt: skip
        jumps = np.abs(np.diff(weather[:, 0]))  # the forecast over its whole length, not only its first value
        limit = f.get("max_forecast_gap_c") or DEFAULT_FORECAST_GAP_C
        if len(jumps) and jumps.max() > limit:
            k = int(np.argmax(jumps))
            return (f"forecast.outdoor_drybulb_c jumps {jumps[k]:.1f} K from its value {k} ({weather[k, 0]:.1f} °C) "
                    f"to its value {k + 1} ({weather[k + 1, 0]:.1f} °C) in one step (threshold {limit} K)")  # fmt: skip
        limit = f.get("max_step_spread_k")  # contracts exported before 2026-12-07 have none
        if limit is not None and step_spread > limit:
            return (f"the model's members disagree by {step_spread:.2f} K about a zone temperature at the end of the "
                    f"coming step with the last setpoints held: the model has not seen this state (threshold "
                    f"{limit} K, calibrated on the building's own record)")  # fmt: skip
        if spread_k > f["max_spread_k"]:
            return (f"the model's members disagree by {spread_k:.2f} K about a zone temperature along the plan "
                    f"(threshold {f['max_spread_k']} K)")  # fmt: skip
        return None

    def _input_name(self, i: int, row: np.ndarray) -> tuple[str, str]:
        """Model input `i` of `row` as the contract names what it comes from, and its value in the contract's units
        ("" for the clock): a sensor (or `power_w - hvac_power_w`, the power that is not HVAC's),
        `last_setpoints.NAME`, `forecast.NAME` (its first value) or `time` (the clock, or the building's schedule,
        at the step's end)."""
        layout, state, a = self.layout, self.layout.state_names, len(self.names)
        if i < len(state):
            units = {s["name"]: s["unit"] for s in self.contract.sensors}
            name = state[i]
            if name not in units:  # the total power less the HVAC's: not a sensor of its own
                name, unit = f"{' + '.join(layout.energy)} - {' + '.join(layout.hvac)}", units[layout.energy[0]]
            else:
                unit = units[name]
            return name, f"{row[i]:.6g} {unit}, "
        k = i - len(state)
        if k < 2 * a:  # the last setpoints, as both the model's previous and its current action
            output = self.contract.outputs[k % a]
            value = from_unit(row[len(state) : len(state) + a], self.low, self.high)[k % a]
            return f"last_setpoints.{output['name']}", f"{value:.6g} {output['unit']}, "
        k -= 2 * a
        if k < len(WEATHER):  # the forecast's first value (or the persisted one)
            variable = self.forecast["variables"][k]
            value = row[i] / WEATHER_SCALE[k]
            return f"forecast.{variable['name']} (its first value)", f"{value:.6g} {variable['unit']}, "
        return "time (the clock's hour and weekday, or the building's schedule then, at the end of the step)", ""


_CALENDAR = ("comfort_seen", "comfort_applied", "bound_sum", "bound_seen", "dated_runs", "dated_bounds",
             "dated_weekday", "dated_applies", "own_runs", "own_actions")  # fmt: skip


def calendar_arrays(calendar: Calendar) -> dict[str, np.ndarray]:
    """The calendar's arrays as planner.npz stores them."""
    state = calendar.state()
    assert set(state) <= set(_CALENDAR), set(state) - set(_CALENDAR)
    return state
