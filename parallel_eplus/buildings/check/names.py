"""`parallel-eplus building check`: every name in a spec resolved against the model before any training step.

A typo in a variable, key or actuator would otherwise cost a hung worker or, worse, a silent zero observation
for a whole run. The check runs the model through the EnergyPlus API in a child process (killable, so nothing
outlives it), asks EnergyPlus for a handle to every variable, meter and actuator the spec names at the first
timestep whose data is ready, and reports every problem at once, each naming the spec key, the value and
the closest names EnergyPlus offers. A passing check is cached by the contents of the spec, the model and the
weather, so `train`, `evaluate` and the env can run it first at almost no cost.
"""

from __future__ import annotations

import argparse
import difflib
import hashlib
import json
import os
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

from parallel_eplus.buildings.spec.load import BuildingSpec, SpecError, load_spec

if TYPE_CHECKING:
    from parallel_eplus.buildings.building import Building

CHECK_TIMEOUT_S = 300.0  # sizing a large model can take a minute on a busy machine


@dataclass(frozen=True)
class CheckResult:
    """The outcome of one check: every problem (none if it passed), the model's control steps per hour."""

    problems: tuple[str, ...]
    timesteps_per_hour: int
    seconds: float
    cached: bool = False
    notes: tuple[str, ...] = ()  # not failures: e.g. an action whose read-back (--init-from-baseline) is unknown

    @property
    def ok(self) -> bool:
        return not self.problems


def cache_dir() -> Path:
    """Where passing checks are remembered (`$XDG_CACHE_HOME/parallel-eplus/checks`)."""
    base = os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache"
    return Path(base) / "parallel-eplus" / "checks"


CHECK_VERSION = b"3"  # what a check proves (2: read-backs, on the prepared copy; 3: node setpoints reach their
# nodes): older passes do not count


def _digest(spec: BuildingSpec, weather: Path) -> str:
    h = hashlib.sha256(CHECK_VERSION)
    for path in (spec.path, spec.idf, weather):
        h.update(Path(path).read_bytes())
        h.update(b"\0")
    return h.hexdigest()[:32]


def _weather_of(spec: BuildingSpec, weather: str | Path | None) -> Path:
    if weather is not None:
        from parallel_eplus.buildings.weather.files import resolve_weather

        return Path(resolve_weather(str(spec.weathers.get(str(weather), weather))))
    if spec.weathers:
        return Path(next(iter(spec.weathers.values())))
    from parallel_eplus.buildings.resources import weather_file

    return weather_file("USA_CA_San.Francisco.Intl.AP.724940_TMY3.epw")


def _requests(spec: BuildingSpec) -> dict:
    """What the probe resolves: (spec key, kind, names) for every variable, meter and actuator."""
    items = []  # [where, kind, names, required]: one that is not required gives a note, not a problem
    for i, o in enumerate(spec.observations):
        if o.meter:
            items.append([f"observations[{i}]", "meter", [o.meter], True])
        else:
            items.append([f"observations[{i}]", "variable", [o.variable, o.key], True])
    for i, a in enumerate(spec.actions):
        for j, act in enumerate(a.actuators):
            items.append([f"actions[{i}].actuators[{j}]", "actuator", [act.component, act.control, act.key], True])
        if a.readback:  # what --init-from-baseline reads; an inferred one that fails is a note
            items.append([f"actions[{i}].readback", "variable", list(a.readback), a.readback_named is not None])
    from parallel_eplus.buildings.idf.takeover import taken_setpoints

    return {"idf": str(spec.idf), "items": items, "takeover": [list(t) for t in taken_setpoints(spec.actions)]}


def _unknown_readbacks(spec: BuildingSpec) -> list[str]:
    return [
        f'actions[{i}].readback: none known for "{a.actuators[0].component}/{a.actuators[0].control}": name the '
        'output variable holding what the building\'s own controls set (readback = { variable = "...", key = "..." }) '
        "to use --init-from-baseline"
        for i, a in enumerate(spec.actions)
        if a.actuators and a.readback is None
    ]


def _late_actions(spec: BuildingSpec) -> list[str]:
    """Notes where actions act a zone timestep late: set after the HVAC managers (building.py
    `applies_before_predictor`), thermostats after the zone predictor read them, and taken-over node setpoints after
    the managers that follow them (MixedAir: the coils' setpoints) computed theirs."""
    from parallel_eplus.buildings.building import PREDICTOR_ACTUATORS, applies_before_predictor
    from parallel_eplus.buildings.idf.prepare import takeover_report

    if applies_before_predictor(spec):
        return []
    kinds = {x.component.lower() for a in spec.actions for x in a.actuators}
    where = ("are all set after the HVAC managers (where fan flows and the nodes a manager still sets must be), so "
             "{} a zone timestep late. A spec whose actions are all thermostat setpoints and node setpoints taken "
             "over from the model's managers sets them before the predictor.")  # fmt: skip
    notes = []
    if kinds & PREDICTOR_ACTUATORS:
        notes.append("actions: thermostat setpoints beside other actuators " + where.format(
            "the zone predictor has read the thermostats: their setpoints act"))  # fmt: skip
    followers = takeover_report(spec.idf, spec.actions).followers
    if followers:
        notes.append("actions: node setpoints beside other actuators " + where.format(
            f"the managers that follow them ({followers[0].kind} \"{followers[0].name}\", ...) see them"))  # fmt: skip
    return notes


def _reach(spec: BuildingSpec, epw: Path) -> tuple[list[str], tuple[str, ...]]:
    """The prepared copy's report (which managers it replaced) and the proof that each node action reaches its node."""
    from parallel_eplus.buildings.check.reach import prove_reach
    from parallel_eplus.buildings.idf.prepare import takeover_report

    problems, notes, reaches = prove_reach(spec, epw)
    done = [r.text() for r in reaches if r.ok]
    report = [f"prepared copy: {line}" for line in takeover_report(spec.idf, spec.actions).lines()]
    return problems, tuple(report + notes + done)


def check_spec(
    spec: BuildingSpec | str | Path, weather: str | Path | None = None, use_cache: bool = True
) -> CheckResult:
    """Resolve every name in the spec through EnergyPlus; never raises for problems in the spec (see `problems`)."""
    spec = spec if isinstance(spec, BuildingSpec) else load_spec(spec)
    epw = _weather_of(spec, weather)
    cached = cache_dir() / f"{_digest(spec, epw)}.json"
    if use_cache and cached.is_file():
        data = json.loads(cached.read_text())
        return CheckResult((), data["timesteps_per_hour"], 0.0, True, tuple(data.get("notes", ())))
    t0 = time.monotonic()
    with tempfile.TemporaryDirectory(prefix="eplus-check-") as tmp:
        request = Path(tmp, "request.json")
        request.write_text(json.dumps(_requests(spec)))
        cmd = [
            sys.executable,
            "-m",
            "parallel_eplus.buildings.check.names",
            "--probe",
            str(request),
            "--weather",
            str(epw),
        ]
        try:
            proc = subprocess.run(cmd, capture_output=True, text=True, timeout=CHECK_TIMEOUT_S, cwd=tmp)
        except subprocess.TimeoutExpired:  # run() kills the child before raising
            late = f"idf: EnergyPlus did not reach its first timestep in {CHECK_TIMEOUT_S:.0f} s"
            return CheckResult((late,), 0, 0.0)
        report = Path(tmp, "report.json")
        if not report.is_file():
            tail = (proc.stderr or proc.stdout)[-1500:].strip()
            return CheckResult((f'idf: EnergyPlus rejected "{spec.idf}" before its first timestep:\n{tail}',), 0, 0.0)
        data = json.loads(report.read_text())
    problems = list(data["problems"])
    tph = int(data["timesteps_per_hour"])
    if spec.timesteps_per_hour is not None and tph and spec.timesteps_per_hour != tph:
        problems.append(f"timesteps_per_hour: {spec.timesteps_per_hour}, but the model's Timestep gives {tph}")
    notes = tuple(data.get("notes", [])) + tuple(_unknown_readbacks(spec)) + tuple(_late_actions(spec))
    if not problems:  # every name resolves: do the node-setpoint actions move their nodes? (buildings/check/reach.py)
        reach_problems, reach_notes = _reach(spec, epw)
        problems += reach_problems
        notes += reach_notes
    result = CheckResult(tuple(problems), tph, time.monotonic() - t0, notes=notes)
    if result.ok and use_cache:
        cached.parent.mkdir(parents=True, exist_ok=True)
        tmp_file = cached.with_suffix(f".{os.getpid()}.tmp")
        tmp_file.write_text(json.dumps({"spec": str(spec.path), "timesteps_per_hour": tph, "notes": notes}))
        os.replace(tmp_file, cached)
    return result


def require_checked(spec: BuildingSpec | str | Path, weather: str | Path | None = None) -> CheckResult:
    """`check_spec`, raising SpecError with every problem."""
    spec = spec if isinstance(spec, BuildingSpec) else load_spec(spec)
    result = check_spec(spec, weather)
    if not result.ok:
        lines = "\n  ".join(result.problems)
        raise SpecError(f"{spec.path}: {len(result.problems)} problem(s) against {spec.idf.name}:\n  {lines}")
    return result


def check_building(
    building: str | Path | Building, weather: str | Path | None = None, use_cache: bool = True
) -> BuildingSpec:
    """Check a spec (a path, a built-in name, or the `Building` a command resolved) against its model; the spec,
    or SpecError."""
    from parallel_eplus.buildings.building import load_building

    spec = load_building(building).spec  # the object the engine reads too
    result = check_spec(spec, weather, use_cache=use_cache)
    if not result.ok:
        lines = "\n  ".join(result.problems)
        raise SpecError(f"{spec.path}: {len(result.problems)} problem(s) against {spec.idf.name}:\n  {lines}")
    return spec


# --- the child process: EnergyPlus through its API, stopped at the first timestep with data ready ---


_IDF_NAMES: dict[str, str] = {}  # upper-case -> as written in the IDF: EnergyPlus lists keys upper-case


def _close(value: str, names, what: str = "") -> str:
    match = difflib.get_close_matches(value.upper(), [n.upper() for n in names], n=1, cutoff=0.6)
    if not match:
        return ""
    original = next(n for n in names if n.upper() == match[0])
    return f'; close: "{_IDF_NAMES.get(original.upper(), original)}"'


def _diagnose(kind: str, names: list[str], listing: list[list[str]]) -> str:
    """Why a name did not resolve, with the nearest names EnergyPlus lists for this model."""
    if kind == "meter":
        meters = [r[1] for r in listing if r[0] == "OutputMeter"]
        if names[0].upper() in (m.upper() for m in meters):
            return (
                f'meter "{names[0]}" is listed, but EnergyPlus 25.2 gives no handle to it at run time; '
                'for facility power use variable "Facility Total Electricity Demand Rate", key "Whole Building"'
            )
        return f'no meter "{names[0]}"{_close(names[0], meters, "meter")}'
    if kind == "variable":
        variable, key = names
        rows = [r for r in listing if r[0] == "OutputVariable"]
        keys = [r[2] for r in rows if r[1].upper() == variable.upper()]
        if keys:
            return f'no key "{key}" for variable "{variable}"{_close(key, keys, "key")}'
        return f'no output variable "{variable}"{_close(variable, sorted({r[1] for r in rows}), "variable")}'
    component, control, key = names
    rows = [r for r in listing if r[0] == "Actuator"]
    same = [r for r in rows if r[1].upper() == component.upper() and r[2].upper() == control.upper()]
    if same:
        return f'no actuator "{component}/{control}" on "{key}"{_close(key, [r[3] for r in same], "key")}'
    pairs = sorted({f"{r[1]}/{r[2]}" for r in rows})
    return f'no actuator type "{component}/{control}"{_close(f"{component}/{control}", pairs, "type")}'


def _probe(request_file: Path, weather: Path) -> None:
    from pyenergyplus.api import EnergyPlusAPI

    from parallel_eplus.buildings.idf.prepare import prepare_idf
    from parallel_eplus.buildings.starter.survey import api_listing
    from parallel_eplus.buildings.starter.write import _idf_names

    request = json.loads(request_file.read_text())
    _IDF_NAMES.update(_idf_names(Path(request["idf"])))
    api = EnergyPlusAPI()
    state = api.state_manager.new_state()
    api.runtime.set_console_output_status(state, False)
    for _, kind, names, _ in request["items"]:
        if kind == "variable":
            api.exchange.request_variable(state, names[0], names[1])
    report: dict = {}

    def on_step(s) -> None:
        if report or not api.exchange.api_data_fully_ready(s):
            return
        listing = api_listing(api, s)
        problems, notes = [], []
        for where, kind, names, required in request["items"]:
            if kind == "variable":
                handle = api.exchange.get_variable_handle(s, *names)
            elif kind == "meter":
                handle = api.exchange.get_meter_handle(s, names[0])
            else:
                handle = api.exchange.get_actuator_handle(s, *names)
            if handle < 0:
                (problems if required else notes).append(f"{where}: {_diagnose(kind, names, listing)}")
        report.update(problems=problems, notes=notes, timesteps_per_hour=api.exchange.num_time_steps_in_hour(s))
        api.runtime.stop_simulation(s)

    api.runtime.callback_begin_zone_timestep_after_init_heat_balance(state, on_step)
    model = request_file.parent / "model.idf"  # the copy every run prepares (buildings/idf/prepare.py)
    prepare_idf(Path(request["idf"]), model, run_days=1, takeover=tuple(map(tuple, request.get("takeover", ()))))
    api.runtime.run_energyplus(state, ["-d", str(request_file.parent / "out"), "-w", str(weather), str(model)])
    if report:
        Path(request_file.parent, "report.json").write_text(json.dumps(report))
    else:
        err = request_file.parent / "out" / "eplusout.err"
        sys.stderr.write(err.read_text(errors="replace")[-1500:] if err.is_file() else "no eplusout.err\n")


def main(argv: list[str] | None = None) -> int:
    """The child process of a check: `--probe REQUEST.json --weather EPW` writes report.json beside it."""
    p = argparse.ArgumentParser(prog="python -m parallel_eplus.buildings.check.names")
    p.add_argument("--probe", type=Path, required=True)
    p.add_argument("--weather", type=Path, required=True)
    args = p.parse_args(argv)
    _probe(args.probe, args.weather)
    return 0


if __name__ == "__main__":
    sys.exit(main())
