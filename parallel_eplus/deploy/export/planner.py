"""`parallel-eplus export runs/<mpc-run>`: a model-based planner as files a server runs without torch or EnergyPlus.

Written: ensemble.onnx (every member's one-step prediction for a batch of candidates, ensemble_graph.py),
rollout.onnx (the same forward over the planner's horizon in one call, `build_rollout`), planner.npz (the action
support, the comfort calendar, the normalizers, and the building's own setpoints at every step of a year for the
fallback, own_setpoints.py) and controller.json (the contract: readings, setpoints, the last setpoints and the
forecast block a request carries, a first request the planner answers (`example`), the planner's settings, the
fallback's thresholds, provenance). The own setpoints come from a year of the building's own controls on the
planner's training weathers, made here (a minute or two), whatever the run trained on: the schedules are the
building's, not the run's. On that record the members' disagreement about the coming step is calibrated
(`max_step_spread_k`: twice the largest on it), and the contract's first setpoints (`outputs[].initial`) are ones
the model has seen. Before anything is final, the served planner (planner_runtime.py) answers sampled decisions of
that run and must give exactly the in-process planner's setpoints.
"""

from __future__ import annotations

import datetime as dt
import hashlib
import json
import logging
import shutil
import tempfile
from dataclasses import asdict, fields
from pathlib import Path

import numpy as np

from parallel_eplus import io
from parallel_eplus.buildings.building import load_building
from parallel_eplus.buildings.resources import saved_building
from parallel_eplus.buildings.scaling import to_unit
from parallel_eplus.buildings.weather.forecast import WEATHER, WEATHER_UNITS
from parallel_eplus.deploy.serve.contract import CONTRACT_FILE, Contract, output_entries, sensor_entries
from parallel_eplus.deploy.serve.own_setpoints import own_table
from parallel_eplus.deploy.serve.planner_runtime import (
    ENSEMBLE_FILE,
    PLANNER_ARRAYS,
    ROLLOUT_FILE,
    PlannerRuntime,
    calendar_arrays,
)
from parallel_eplus.deploy.serve.served_rule import rule_entry
from parallel_eplus.learning.model_based.runtime.ensemble_graph import INPUT, OUTPUT
from parallel_eplus.learning.model_based.runtime.features import step_times
from parallel_eplus.learning.model_based.runtime.planner import PlannerSettings

log = logging.getLogger(__name__)

PLANNER_FORMAT = 2  # a planner's contract: servers that read only policies (format 1) refuse it
SAMPLED_DECISIONS = 48
PLANNER_SETTINGS = tuple(f.name for f in fields(PlannerSettings))  # what a served plan needs
PARITY_TOLERANCE = 1e-5  # physical units, as a policy's export (float32 actions scaled in float64)
CALIBRATION_ROWS = 2000  # steps of the own record on which the members' disagreement is measured
STEP_SPREAD_FACTOR = 2.0  # max_step_spread_k: this times the largest disagreement on the own record
MIN_STEP_SPREAD_K = 0.05
INITIAL_Z = 2.0  # an output's spec `initial` further than this from the data's mean is replaced (outputs[].initial)


def own_controls(building: str | None, weathers: list[str], days: int, workers: int, step_minutes: float,
                 progress: bool = True):  # fmt: skip
    """(planner.npz's own-setpoint arrays, the run): what the building's own controls set (physical) at each step of
    a run of `days` on `weathers`; the table from the first weather's (own_setpoints.py)."""
    from parallel_eplus.learning.imitation import record_baseline

    with tempfile.TemporaryDirectory(prefix="parallel-eplus-own-") as folder:
        demos = record_baseline(building, weathers, days, workers, Path(folder), progress=progress)
    first = [r for r, w in enumerate(demos.weathers) if w == demos.weathers[0]]
    table = own_table([demos.times[r] for r in first], demos.physical[first], step_minutes)
    return table, demos


def _sha256(path: Path) -> str:
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


def export_planner(source: Path, out_dir: Path, workers: int = 2, max_input_z: float = 6.0,
                   max_forecast_gap_c: float = 6.0, max_spread_k: float | None = None, persistence: bool = False,
                   record_days: int | None = None, options: str | None = None, progress: bool = True,
                   ) -> Path:  # fmt: skip
    """Write the planner at `source` (planner.pt) into `out_dir`; returns the contract's path. `record_days`: how
    long the own controls are recorded for the fallback's setpoints (default: a year, whatever the run's episodes).
    `options`: settings overriding the planner's own, as `evaluate --planner` gives them (not its forecast: the
    served planner reads the one each request carries). `progress`: a progress bar while recording."""
    from parallel_eplus.learning.model_based.control.mpc import MPC
    from parallel_eplus.learning.model_based.control.saved_planner import PlannerOptions
    from parallel_eplus.learning.model_based.runtime.ensemble_graph import build_graph, build_rollout

    saved_path = source.parent / "config.json"
    saved = json.loads(saved_path.read_text()) if saved_path.is_file() else {}
    building_name = saved_building(saved)
    chosen = PlannerOptions.parse(options, flag="--planner-options")
    if chosen.forecast != "perfect":
        raise ValueError("--planner-options forecast: a served planner reads the forecast each request carries")
    mpc = chosen.apply(MPC.load(source))
    building = load_building(mpc.building)
    rule = None
    if mpc.settings.baseline_source == "rule":  # the rule it rides is served beside it (served_rule.py) or refused
        rule = rule_entry(mpc.rule(0), [s.name for s in building.observed])
    spec = building.spec
    weathers = saved.get("weathers") or list(spec.weathers)[:1] or ["CA"]
    days = record_days or 365
    log.info("recording the building's own controls on %s (%d days) for the fallback's setpoints", weathers, days)
    own, demos = own_controls(mpc.building, weathers, days, workers, mpc.step_minutes, progress)

    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    arrays = mpc.model.arrays()
    io.write_bytes(out_dir / ENSEMBLE_FILE, build_graph(arrays))
    n_temps = len(mpc.layout.temperatures)
    io.write_bytes(out_dir / ROLLOUT_FILE, build_rollout(arrays, mpc.settings.horizon, n_temps))
    with io.atomic_path(out_dir / PLANNER_ARRAYS) as tmp, open(tmp, "wb") as f:
        np.savez(f, support_low=mpc.support[0], support_high=mpc.support[1], **own, x_mean=arrays.x_mean,
                 x_std=arrays.x_std, **calendar_arrays(mpc.comfort_times))  # fmt: skip

    outdoor = next((o.name for o in building.observed if o.variable.lower() == "site outdoor air drybulb temperature"),
                   None)  # fmt: skip
    inputs, outputs = sensor_entries(building), output_entries(building)
    for entry, value in zip(outputs, _initial(building.actions, demos, arrays, mpc.layout), strict=True):
        entry["initial"] = value  # what a first request's last setpoints are
    settings = asdict(mpc.settings)
    contract = {
        "format": PLANNER_FORMAT,
        "kind": "planner",
        "onnx": {"file": ENSEMBLE_FILE, "input": INPUT, "output": OUTPUT, "sha256": _sha256(out_dir / ENSEMBLE_FILE),
                 "meaning": "[members, batch, inputs] -> [members, batch, targets], physical units",
                 "rollout": {"file": ROLLOUT_FILE, "sha256": _sha256(out_dir / ROLLOUT_FILE),
                             "horizon": mpc.settings.horizon, "n_temps": n_temps,
                             "meaning": "the planner's horizon of the same forward in one call (state, last "
                             "action, actions, exogenous -> each member's state after each step)"}},  # fmt: skip
        "arrays": {"file": PLANNER_ARRAYS, "sha256": _sha256(out_dir / PLANNER_ARRAYS)},
        "inputs": inputs,
        "time": {"required": True, "meaning": "the building's local date and time at the start of the step the "
                 "setpoints are for (standard time, as EnergyPlus runs)"},  # fmt: skip
        "outputs": outputs,
        "last_setpoints": {"required": True, "meaning": "the setpoints in force during the step that just ended, "
                           "by output name, physical units"},  # fmt: skip
        "forecast": {
            "required": not persistence, "missing": "persistence" if persistence else "refuse",
            "steps": mpc.settings.horizon, "step_s": int(60 * mpc.step_minutes),
            "meaning": "each variable's value at the end of each of the coming control steps",
            "variables": [{"name": n, "unit": u} for n, u in zip(WEATHER, WEATHER_UNITS, strict=True)],
            "sensor": outdoor,
        },
        "plan": {"required": False, "meaning": "the last answer's `plan` (the rest of its plan, normalized "
                 "increments), sent back to warm-start the search; without it the search starts from holding"},
        "guard": None if mpc.settings.guard_k is None else {
            "required": False, "meaning": "the last answer's `guard` (steps it still plays the own plan, steps since "
            "it last left it, and the discomfort the model predicted for the own plan's step), sent back so the "
            "planner can test what leaving the own plan cost; without it the guard starts afresh"},
        "rule": rule,
        "demand_peaks_kw": None if not mpc.demand else {
            "required": False, "charges": mpc.demand.charges.names,
            "meaning": "each demand charge's highest 15-minute facility demand so far this month within its window, "
                       "kW, by charge name; a charge not given has none yet (its whole demand is a new peak)"},
        "planner": {
            "settings": {k: settings[k] for k in PLANNER_SETTINGS},
            "margin_c": mpc.margin_c, "power_weight": mpc.power_weight, "comfort_weight": mpc.comfort_weight,
            "seed": mpc.seed, "step_minutes": mpc.step_minutes,
            "layout": asdict(mpc.layout), "calendar": mpc.comfort_times.settings(),
            "comfort_reference": mpc.settings.comfort_reference, "thermostat_sides": mpc.thermostat_sides,
            "schedule": [list(p) for p in mpc.forecasts(weathers[0]).schedule or ()] or None,
            "energy": mpc.energy_weights.entry(_tariff_values(mpc.energy_weights, spec, out_dir)),
            "demand": None if not mpc.demand else {"power": mpc.power, "part": mpc.demand.charges.part,
                                                   "per_dollar": mpc.demand.charges.per_dollar},
        },  # fmt: skip
        "fallback": {"max_input_z": max_input_z, "max_forecast_gap_c": max_forecast_gap_c if outdoor else None,
                     "max_spread_k": max_spread_k, "exogenous": mpc.exogenous_names,
                     "own_controls": f"{PLANNER_ARRAYS}: own_controls [runs, output], own_controls_at [runs], "
                     f"own_controls_weekday [366]: the building's own setpoints at each step of {days} days from "
                     f"January 1 on {weathers[0]}, read at the nearest date with the request's weekday"},  # fmt: skip
        "control_step_s": int(60 * mpc.step_minutes),
        "building": {"name": spec.name, "spec": spec.path.name, "sha256": _sha256(spec.path)},
        "policy": {"algorithm": "mpc", "model": source.name, "sha256": _sha256(source), "run":
                   saved.get("run_name", source.parent.parent.name), "seed": saved.get("seed"),
                   "weathers": saved.get("weathers"), "timesteps": saved.get("timesteps"), "building": building_name},
        "exported": dt.datetime.now(dt.UTC).isoformat(timespec="seconds"),
    }  # fmt: skip
    spreads, diff, peaked, held = _check(out_dir, contract, mpc, demos)
    if contract["fallback"]["max_spread_k"] is None:  # 3 x the largest spread on the building's own days, >= 0.5 K
        contract["fallback"]["max_spread_k"] = round(max(0.5, 3 * float(np.max(spreads))), 3)
    # what the model has seen, its members agree on: twice their largest disagreement on the own record trips
    contract["fallback"]["max_step_spread_k"] = round(max(MIN_STEP_SPREAD_K, STEP_SPREAD_FACTOR * float(held.max())), 3)
    contract["export_check"] = {
        "decisions": len(spreads),
        "max_abs_diff": diff,
        "spread_k_median": round(float(np.median(spreads)), 4),
        "spread_k_max": round(float(np.max(spreads)), 4),
        "decisions_with_demand_peaks": peaked,
        "step_spread_rows": len(held),
        "step_spread_k_median": round(float(np.median(held)), 4),
        "step_spread_k_max": round(float(held.max()), 4),
    }
    contract["example"] = _example(out_dir, contract, mpc, demos)
    path = out_dir / CONTRACT_FILE
    io.write_text(path, json.dumps(contract, indent=2) + "\n")
    log.info("exported the planner %s -> %s (%d sampled decisions equal in process; fallback beyond %.2f K spread)",
             source, out_dir, len(spreads), contract["fallback"]["max_spread_k"])  # fmt: skip
    return path


def _tariff_values(weights, spec, out_dir: Path) -> dict[str, object]:
    """Each priced fuel's tariff as the spec gives it (a fuel it does not name: the default price), a price series'
    CSV copied beside the contract: what the served planner prices its horizon with."""
    from parallel_eplus.buildings.pricing.tariff import DEFAULT_PRICES

    named, values = dict(spec.kpis.tariff), {}
    for fuel in weights.tariffs:
        value = named.get(fuel, DEFAULT_PRICES.get(fuel, 0.0))
        if isinstance(value, dict) and "csv" in value:
            name = f"tariff-{fuel}.csv"
            shutil.copyfile((spec.path.parent / value["csv"]).expanduser(), out_dir / name)
            value = dict(value, csv=name)
        values[fuel] = value
    return values


def _last(demos, r: int) -> np.ndarray:
    """The setpoints in force before step `r` of the own-controls run, within the outputs' ranges: the own controls
    are not bound by them (the large hotel's DOAS node read 10 C against [12, 22]), a served planner's
    `last_setpoints` are."""
    return np.clip(demos.physical[max(r - 1, 0)], demos.low, demos.high)


def _body(contract: dict, mpc, demos, r: int) -> tuple[dict, dict]:
    """Step `r` of the own-controls run as a request (its readings, the last step's setpoints, the weather file's
    forecast), and as the in-process planner's info."""
    names = [o["name"] for o in contract["outputs"]]
    sensors = [i["name"] for i in contract["inputs"]]
    t, weather, obs = demos.times[r], demos.weathers[r], demos.observations[r]
    info = {"time": t, "weather": weather}
    if contract["rule"]:  # what the rule reads, in process (info) as in the request (sensors, rule_readings)
        info |= dict(zip(sensors, map(float, obs[: len(sensors)]), strict=True))
        info |= {upper: float(demos.bounds[r][k][1]) for k, (_, upper) in enumerate(mpc.rule(0).points.zones)}
    times = step_times(t, mpc.step_minutes, mpc.settings.horizon)
    truth = mpc.forecasts(weather).file.truth(times)
    body = {
        "time": t.isoformat(), "sensors": dict(zip(sensors, map(float, obs[: len(sensors)]), strict=True)),
        "last_setpoints": dict(zip(names, map(float, _last(demos, r)), strict=True)),
        "forecast": {n: truth[:, i].tolist() for i, n in enumerate(WEATHER)},
    }  # fmt: skip
    if contract["rule"]:
        body["rule_readings"] = {e["name"]: info[e["name"]] for e in contract["rule"]["readings"]}
    return body, info


def _initial(actions, demos, arrays, layout) -> list[float]:
    """Each output's first setpoint (`outputs[].initial`): the spec's `initial` where the data the model learned
    from holds it (within INITIAL_Z standard deviations of its mean as a last and as a next action), else the value
    the building's own controls set most often that is nearest the data's mean (a setback group's 21 °C at 29
    standard deviations from a model that saw 15.6 °C: issue 87)."""
    ns, a_n, out = layout.n_state, len(actions), []
    for i, action in enumerate(actions):
        mean = np.array([arrays.x_mean[ns + i], arrays.x_mean[ns + a_n + i]])
        std = np.array([arrays.x_std[ns + i], arrays.x_std[ns + a_n + i]])

        def z(value, action=action, mean=mean, std=std) -> float:
            return float(np.max(np.abs(to_unit(np.float64(value), action.low, action.high) - mean) / std))

        if z(action.initial) <= INITIAL_Z:
            out.append(action.initial)
            continue
        values, counts = np.unique(np.round(demos.physical[:, i], 4), return_counts=True)
        inside = [v for v in values if z(v) <= INITIAL_Z] or [min(values, key=z)]
        out.append(float(max(inside, key=lambda v: counts[np.searchsorted(values, v)])))
        log.info("%s: first setpoint %g (the spec's %g is %.1f standard deviations from the data)", action.name,
                 out[-1], action.initial, z(action.initial))  # fmt: skip
    return out


def _example(out_dir: Path, contract: dict, mpc, demos) -> dict:
    """The contract's documented first request (`example`): a step of the own-controls run with the outputs'
    `initial` as its last setpoints, one the planner answers without falling back (checked here with the final
    thresholds); the step's own setpoints as last ones where no step takes the `initial` ones."""
    runtime = PlannerRuntime(out_dir, Contract(contract))
    initial = {o["name"]: o["initial"] for o in contract["outputs"]}
    rows = np.linspace(1, len(demos) - 1, SAMPLED_DECISIONS).astype(int)
    for last in (initial, None):
        for r in rows:
            body = _body(contract, mpc, demos, int(r))[0]
            if last is not None:
                body["last_setpoints"] = dict(last)
            if not runtime.act(body)["fallback"]:
                return body
    log.warning("every sampled step of the own controls' record falls back: the contract's example does too")
    return body


def _check(out_dir: Path, contract: dict, mpc, demos) -> tuple[np.ndarray, float, int, np.ndarray]:
    """Served vs in-process on decisions sampled from the own-controls run: (each decision's spread, the largest
    setpoint difference, physical units, how many carried demand peaks, and the members' disagreement about the
    coming step on up to CALIBRATION_ROWS steps of the run). Any difference is refused. Under demand charges each
    decision carries the month's running peaks from the readings of the day before it, in process and in its
    request."""
    draft = dict(contract, fallback=dict(contract["fallback"], max_spread_k=float("inf"), max_input_z=float("inf"),
                                         max_forecast_gap_c=None, max_step_spread_k=None))  # fmt: skip
    runtime = PlannerRuntime(out_dir, Contract(draft))
    rows = np.linspace(1, len(demos) - 1, SAMPLED_DECISIONS).astype(int)
    names = [o["name"] for o in contract["outputs"]]
    spreads, diff, peaked = [], 0.0, 0
    for r in rows:
        body, info = _body(contract, mpc, demos, r)
        t, weather, obs = demos.times[r], demos.weathers[r], demos.observations[r]
        mpc.reset(0)
        if mpc.demand:  # the month's peaks so far, kept in process and sent as a client keeps them
            day = int(round(24 * 60 / mpc.step_minutes))
            history = [q for q in range(max(0, r - day), r + 1) if demos.weathers[q] == weather]
            for q in history:
                mpc.observe(demos.observations[q][None], [{"time": demos.times[q], "weather": weather}])
            body["demand_peaks_kw"] = mpc.demand.trackers[0].month_peaks(mpc.demand.charges.names, t)
            peaked += bool(body["demand_peaks_kw"])
        answer = runtime.act(body)
        a_last = to_unit(_last(demos, r)[None], demos.low, demos.high).astype(np.float32)
        expected = demos.to_physical(mpc.act(obs[None], [info], a_last)[0])
        served = np.array([answer["setpoints"][n]["value"] for n in names])
        diff = max(diff, float(np.max(np.abs(served - expected))))
        spreads.append(answer["spread_k"])
    if diff > PARITY_TOLERANCE:
        raise ValueError(f"the served planner's setpoints differ from the in-process planner's by {diff:g}")
    calibration = np.unique(np.linspace(1, len(demos) - 1, min(CALIBRATION_ROWS, len(demos) - 1)).astype(int))
    held = runtime.held_spreads([_body(contract, mpc, demos, int(r))[0] for r in calibration])
    return np.array(spreads), diff, peaked, held
