"""What an EnergyPlus model offers an agent: EnergyPlus's own listing and one simulated day of values.

The model runs through the EnergyPlus API until one day of its weather run period has passed (warm-up is not
counted), as the engine runs it (buildings/idf/prepare.py: the weather year, not the design days), with the variables
a spec usually observes requested for every key: EnergyPlus lists and reads only requested variables.
`building init` (buildings/starter/write.py) writes a starter spec from the result.
"""

from __future__ import annotations

import csv
import io
import math
import tempfile
from dataclasses import dataclass, field
from pathlib import Path

from parallel_eplus.buildings.idf.prepare import prepare_idf

# Variables requested for every key before the run: EnergyPlus lists (and reads) only requested variables.
REQUESTS = (
    ("Site Outdoor Air Drybulb Temperature", "Environment"),
    ("Zone Mean Air Temperature", "*"),
    ("Facility Total Electricity Demand Rate", "Whole Building"),
    ("Facility Total HVAC Electricity Demand Rate", "Whole Building"),
    ("Facility Total Building Electricity Demand Rate", "Whole Building"),
    ("ITE Air Inlet Dry-Bulb Temperature", "*"),
    ("System Node Setpoint Temperature", "*"),
    ("Zone Thermostat Cooling Setpoint Temperature", "*"),
    ("Zone Thermostat Heating Setpoint Temperature", "*"),
    ("Fan Air Mass Flow Rate", "*"),
    ("System Node Mass Flow Rate", "*"),  # outdoor-air controllers' flows (their actuator node)
)
SERIES = ("System Node Mass Flow Rate", "Fan Air Mass Flow Rate")  # kept step by step: flows read together
RUN_PERIOD_WEATHER = 3  # api.exchange.kind_of_sim
NO_SETPOINT = -900.0  # EnergyPlus marks a node without a setpoint with -999
WEEK = 7.0  # days surveyed: every day type of a weekly schedule. One day saw a DOE prototype's January 1, a Sunday
# and a holiday: fans off, setpoints set back, so bounds and notes came from an empty building.


@dataclass
class Survey:
    """What EnergyPlus says about a model: its API listing and each requested variable's range in a short run."""

    rows: list[list[str]]  # list_available_api_data_csv, section markers dropped
    seen: dict[tuple[str, str], tuple[float, float]] = field(default_factory=dict)  # (variable, KEY) -> (min, max)
    # EnergyPlus's sizing results (eplusout.eio): (object type, NAME upper case, field) -> value, e.g.
    # ("Controller:OutdoorAir", "VAV_1_OA_CONTROLLER", "Minimum Outdoor Air Flow Rate [m3/s]") -> 0.34
    sizing: dict[tuple[str, str, str], float] = field(default_factory=dict)
    series: dict[tuple[str, str], list[float]] = field(default_factory=dict)  # SERIES' values, step by step
    timesteps_per_hour: int = 0
    days: float = 0.0

    def meters(self) -> set[str]:
        """The model's meters, upper-case."""
        return {r[1].upper() for r in self.rows if r[0] == "OutputMeter" and len(r) > 1}

    def keys(self, kind: str, *names: str) -> list[str]:
        return list(dict.fromkeys(r[-2] for r in self.rows if r[0] == kind and tuple(r[1 : 1 + len(names)]) == names))


def api_listing(api, state) -> list[list[str]]:
    """EnergyPlus's own list of what a running model offers (kind, names..., unit), section markers dropped."""
    text = api.exchange.list_available_api_data_csv(state).decode(errors="replace")
    return [r for r in csv.reader(io.StringIO(text)) if r and not r[0].startswith("**")]


def survey(idf: Path, weather: Path, days: float = WEEK) -> Survey:
    """Run the model through the API until `days` simulated days after warm-up (or its end) and report."""
    from pyenergyplus.api import EnergyPlusAPI

    api = EnergyPlusAPI()
    state = api.state_manager.new_state()
    api.runtime.set_console_output_status(state, False)
    for variable, key in REQUESTS:
        api.exchange.request_variable(state, variable, key)
    result = Survey([])
    handles: dict[tuple[str, str], int] = {}
    steps = [0]

    def on_step(s) -> None:
        if not api.exchange.api_data_fully_ready(s):
            return
        if not result.rows:
            result.rows = api_listing(api, s)
            result.timesteps_per_hour = api.exchange.num_time_steps_in_hour(s)
            for r in result.rows:
                if r[0] == "OutputVariable" and any(r[1] == v for v, _ in REQUESTS):
                    handles[(r[1], r[2])] = api.exchange.get_variable_handle(s, r[1], r[2])
        if api.exchange.warmup_flag(s) or api.exchange.kind_of_sim(s) != RUN_PERIOD_WEATHER:
            return
        for k, h in handles.items():
            value = api.exchange.get_variable_value(s, h)
            low, high = result.seen.get(k, (math.inf, -math.inf))
            result.seen[k] = (min(low, value), max(high, value))
            if k[0] in SERIES:
                result.series.setdefault(k, []).append(value)
        steps[0] += 1
        if steps[0] >= days * 24 * result.timesteps_per_hour:
            api.runtime.stop_simulation(s)

    api.runtime.callback_end_zone_timestep_after_zone_reporting(state, on_step)
    with tempfile.TemporaryDirectory(prefix="eplus-init-") as out:
        model = Path(out, "model.idf")
        prepare_idf(idf, model, max(2, math.ceil(days) + 1))
        code = api.runtime.run_energyplus(state, ["-d", out, "-w", str(weather), str(model)])
        result.sizing = component_sizing(Path(out, "eplusout.eio"))
        err = Path(out, "eplusout.err")
        tail = err.read_text(errors="replace")[-1500:] if err.is_file() else ""
    api.state_manager.delete_state(state)
    if not result.rows:
        raise ValueError(f"{idf}: EnergyPlus stopped before its first timestep (exit code {code}):\n{tail}")
    result.days = steps[0] / (24 * result.timesteps_per_hour)
    return result


def component_sizing(eio: Path) -> dict[tuple[str, str, str], float]:
    """eplusout.eio's `Component Sizing Information` rows: (type, NAME, field with its unit) -> the sized value."""
    out: dict[tuple[str, str, str], float] = {}
    if eio.is_file():
        for row in csv.reader(io.StringIO(eio.read_text(errors="replace"))):
            if len(row) >= 5 and row[0].strip() == "Component Sizing Information":
                try:
                    out[(row[1].strip(), row[2].strip().upper(), row[3].strip())] = float(row[4])
                except ValueError:
                    continue
    return out


def summary(s: Survey) -> list[str]:
    """What EnergyPlus offers, by kind: the long list behind the spec's few candidates."""
    counts: dict[str, int] = {}
    for r in s.rows:
        if r[0] == "Actuator":
            counts[f"{r[1]} / {r[2]}"] = counts.get(f"{r[1]} / {r[2]}", 0) + 1
    top = sorted(counts.items(), key=lambda kv: -kv[1])
    lines = [f"{sum(counts.values())} actuators in {len(counts)} kinds; most common:"]
    lines += [f"  {n:5d}  {kind}" for kind, n in top[:8]]
    for kind in ("Zone Temperature Control / Cooling Setpoint", "System Node Setpoint / Temperature Setpoint",
                 "Fan / Fan Air Mass Flow Rate", "Outdoor Air Controller / Air Mass Flow Rate"):  # fmt: skip
        lines.append(f"  {counts.get(kind, 0):5d}  {kind}  (candidates)")
    variables = [r for r in s.rows if r[0] == "OutputVariable"]
    lines.append(f"{len(variables)} output variables (the model's own Output:Variable requests and ours), "
                 f"{sum(r[0] == 'OutputMeter' for r in s.rows)} meters, "
                 f"{sum(r[0] == 'InternalVariable' for r in s.rows)} internal variables")  # fmt: skip
    return lines
