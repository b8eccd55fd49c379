"""`parallel-eplus building check SPEC`: resolve every observation and actuator of a spec against its model.

EnergyPlus runs the model's first day through the API just until its data are ready, resolves every handle,
reads its own list of what is available (`list_available_api_data_csv`) for close matches, and stops. Every
problem is reported at once, naming the spec key and value. A passed check is remembered per (spec, IDF)
content hash, so train, evaluate and the env can run it first at the cost of a file lookup.
"""

from __future__ import annotations

import csv
import difflib
import hashlib
import io
import json
import os
import tempfile
from pathlib import Path

from parallel_eplus.buildings.spec import BuildingSpec, SpecError, load_spec

CACHE_DIR = Path(os.environ.get("PARALLEL_EPLUS_CACHE", Path.home() / ".cache" / "parallel-eplus")) / "checks"


def _close(value: str, names) -> str:
    """EnergyPlus lists many names upper-cased; match without case, show the name as EnergyPlus lists it."""
    by_lower = {n.lower(): n for n in names}
    match = difflib.get_close_matches(value.lower(), sorted(by_lower), n=1, cutoff=0.6)
    return f'; close: "{by_lower[match[0]]}"' if match else ""


def _available(csv_text: str) -> tuple[set, set, set]:
    """(actuators (component, control, key), variables (name, key), meters) EnergyPlus lists."""
    actuators, variables, meters = set(), set(), set()
    for row in csv.reader(io.StringIO(csv_text)):
        if not row:
            continue
        kind = row[0].strip().lower()
        if kind == "actuator" and len(row) >= 4:
            actuators.add((row[1], row[2], row[3]))
        elif kind == "outputvariable" and len(row) >= 3:
            variables.add((row[1], row[2]))
        elif kind == "outputmeter" and len(row) >= 2:
            meters.add(row[1])
    return actuators, variables, meters


def _problems(spec: BuildingSpec, x, state) -> list[str]:
    actuators, variables, meters = _available(x.list_available_api_data_csv(state).decode(errors="replace"))
    out = []
    for i, o in enumerate(spec.observations):
        where = f"observations[{i}]"
        if o.meter is not None:
            if x.get_meter_handle(state, o.meter) < 0:
                out.append(f'{where}.meter: no meter "{o.meter}"{_close(o.meter, meters)}')
            continue
        if x.get_variable_handle(state, o.variable, o.key) >= 0:
            continue
        keys = [k for v, k in variables if v.lower() == o.variable.lower()]
        if keys:
            out.append(f'{where}.key: no variable "{o.variable}" on "{o.key}"{_close(o.key, keys)}')
        else:
            names = [v for v, _ in variables]
            out.append(f'{where}.variable: no variable "{o.variable}"{_close(o.variable, names)}')
    for i, a in enumerate(spec.actions):
        for j, act in enumerate(a.actuators):
            if x.get_actuator_handle(state, act.component, act.control, act.key) >= 0:
                continue
            where = f"actions[{i}].actuators[{j}]"
            kind = f"{act.component}/{act.control}"
            keys = [
                k for c, t, k in actuators if (c.lower(), t.lower()) == (act.component.lower(), act.control.lower())
            ]
            if keys:
                out.append(f'{where}: no actuator "{kind}" on "{act.key}"{_close(act.key, keys)}')
            else:
                kinds = [f"{c}/{t}" for c, t, _ in actuators]
                out.append(f'{where}: no actuator type "{kind}"{_close(kind, kinds)}')
    return out


def _digest(spec: BuildingSpec) -> str:
    h = hashlib.sha256(spec.path.read_bytes())
    h.update(spec.idf.read_bytes())
    return h.hexdigest()[:32]


def run_check(spec: BuildingSpec, weather: str | Path | None = None) -> list[str]:
    """Every problem EnergyPlus finds with the spec's names (empty: all resolve). Runs EnergyPlus in-process."""
    from pyenergyplus.api import EnergyPlusAPI

    from parallel_eplus.buildings.weather import resolve_weather
    from parallel_eplus.engine.episode import write_episode_idf

    epw = resolve_weather(weather or next(iter(spec.weathers.values()), None) or "CA")
    api = EnergyPlusAPI()
    state = api.state_manager.new_state()
    api.runtime.set_console_output_status(state, False)
    for o in spec.observations:
        if o.variable is not None:
            api.exchange.request_variable(state, o.variable, o.key)
    found: list[list[str]] = []

    def ready(s) -> None:
        if found or not api.exchange.api_data_fully_ready(s):
            return
        try:
            found.append(_problems(spec, api.exchange, s))
        finally:
            api.runtime.stop_simulation(s)

    api.runtime.callback_begin_zone_timestep_before_set_current_weather(state, ready)
    with tempfile.TemporaryDirectory(prefix="parallel-eplus-check-") as tmp:
        idf = Path(tmp) / "model.idf"
        write_episode_idf(spec.idf, idf, 1)
        api.runtime.run_energyplus(state, ["-d", tmp, "-w", str(epw), str(idf)])
        err = (Path(tmp) / "eplusout.err").read_text(errors="replace") if (Path(tmp) / "eplusout.err").is_file() else ""
    api.state_manager.delete_state(state)
    if not found:
        fatal = [line.strip() for line in err.splitlines() if "** Fatal" in line or "** Severe" in line][:5]
        return [f"idf: EnergyPlus stopped before its data were ready: {' | '.join(fatal) or 'no message'}"]
    return found[0]


def check_building(path: str | Path, weather: str | Path | None = None, use_cache: bool = True) -> BuildingSpec:
    """Load and check a spec; raises SpecError listing every problem. Passed checks are cached per content."""
    spec = load_spec(path)
    marker = CACHE_DIR / f"{_digest(spec)}.json"
    if use_cache and marker.is_file():
        return spec
    problems = run_check(spec, weather)
    if problems:
        raise SpecError(f"{spec.path}: {len(problems)} problem(s) against {spec.idf.name}:\n  " + "\n  ".join(problems))
    marker.parent.mkdir(parents=True, exist_ok=True)
    marker.write_text(json.dumps({"spec": str(spec.path), "idf": str(spec.idf)}))
    return spec
