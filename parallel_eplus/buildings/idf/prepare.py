"""The engine's own copy of a model, so that any EnergyPlus model runs its weather year as it is.

Each episode runs `model.idf` written here from the spec's model, never the user's file:
- one RunPeriod, from January 1 for `run_days` days; the model's own day of week, holiday, daylight-saving and
  weather flags are kept (a model without a RunPeriod gets EnergyPlus's defaults);
- SimulationControl runs the weather-file run period and not the sizing periods as environments before it
  (sizing calculations keep the model's setting: they size from the design days without simulating them as
  environments). Prototype models ship running only their design days (the DOE reference buildings);
- EnergyPlus's own CSV off on request (`energyplus_csv=False`): it holds every reported value in memory until
  the run ends (for the data center a year costs 55 MB and 1.4 s) and our step table already has what
  training needs;
- the node setpoints the agent's actions own taken from the model's setpoint managers (buildings/idf/takeover.py);
- on request (`ventilation`), the outdoor air on demand (buildings/idf/ventilation.py).
Objects are found by a small IDF tokenizer that skips comments (idf_text.py), so a commented-out object is never
touched.
"""

from __future__ import annotations

import dataclasses
import datetime as dt
import re
from pathlib import Path

from parallel_eplus.buildings.idf.objects import IdfObject, idf_objects
from parallel_eplus.buildings.idf.takeover import Takeover, plan_takeover, rewrite, taken_setpoints
from parallel_eplus.buildings.idf.ventilation import DemandVentilation, plan_ventilation


def _line_end(text: str, pos: int) -> int:
    """Past the rest of the line when it holds only a comment (an object's last field comment goes with it)."""
    m = re.compile(r"[ \t]*(?:!.*)?\n?").match(text, pos)
    return m.end() if m else pos


def _object(kind: str, fields: list[str], note: str) -> str:
    body = ",\n".join(f"    {f}" for f in fields)
    return f"  {kind},\n{body};  ! {note}"


WEEKDAYS = ("Monday", "Tuesday", "Wednesday", "Thursday", "Friday", "Saturday", "Sunday")


def _run_period(first: IdfObject | None, run_days: int, start_day: int = 1, weekday: str | None = None) -> str:
    """The episode's RunPeriod: `run_days` from day of year `start_day`; `weekday` that day's (a period cut from a
    year starts on the weekday that date had in the year, so the schedules fall as they did)."""
    if not 1 <= run_days <= 365:
        raise ValueError(f"run_days must be within 1..365, got {run_days}")
    if start_day < 1 or start_day + run_days - 1 > 365:
        raise ValueError(f"a run from day {start_day} for {run_days} days passes the end of the year")
    first_day = dt.date(2013, 1, 1) + dt.timedelta(days=start_day - 1)
    end = first_day + dt.timedelta(days=run_days - 1)
    # Name, begin month/day/year, end month/day/year, then the model's own flags (day of week, holidays, ...).
    flags = first.fields[7:] if first is not None else []
    if weekday is None and flags and flags[0].strip().capitalize() in WEEKDAYS:  # the model names January 1's
        weekday = WEEKDAYS[(WEEKDAYS.index(flags[0].strip().capitalize()) + start_day - 1) % 7]
    if weekday is not None:
        flags = [weekday, *flags[1:]]
    fields = ["Episode", str(first_day.month), str(first_day.day), "", str(end.month), str(end.day), "", *flags]
    return _object("RunPeriod", fields, "the episode's, set by parallel-eplus")


def _set_fields(text: str, o: IdfObject, values: dict[int, str]) -> str:
    """The object's text with some fields replaced in place (its comments kept); missing fields are appended."""
    body = text[o.start : o.end]
    n = max([len(o.fields), *(i + 1 for i in values)])
    if n > len(o.fields):  # a short object: rebuild it (EnergyPlus's defaults for the fields it left out)
        fields = o.fields + [""] * (n - len(o.fields))
        return _object(o.kind, [values.get(i, f) for i, f in enumerate(fields)], "set by parallel-eplus")
    for i in sorted(values, reverse=True):
        a, b = (x - o.start for x in o.spans[i])
        body = body[:a] + values[i] + body[b:]
    return body


_WEATHER_YEAR = {3: "No", 4: "Yes"}  # SimulationControl: no sizing periods as environments; the weather year


def _simulation_control(kinds: set[str]) -> str:
    """For a model without one: EnergyPlus's defaults, with the sizing calculations its Sizing objects ask for."""
    fields = ["Yes" if f"sizing:{k}" in kinds else "No" for k in ("zone", "system", "plant")] + ["", ""]
    fields = [_WEATHER_YEAR.get(i, f) for i, f in enumerate(fields)]
    return _object("SimulationControl", fields, "the weather year only, set by parallel-eplus")


def prepare_idf(
    source: Path,
    target: Path,
    run_days: int,
    energyplus_csv: bool = True,
    outputs: tuple[tuple[str, str], ...] = (),
    start_day: int = 1,
    weekday: str | None = None,
    takeover: tuple[tuple[str, str], ...] = (),
    ventilation: bool = False,
) -> Takeover:
    """Write the episode's copy of `source` to `target` (see the module's docstring for what changes); returns what
    it took from the model's setpoint managers.

    `outputs`: (key, variable) pairs reported every timestep in EnergyPlus's CSV (which they turn on).
    `start_day`, `weekday`: the run period's first day of the year and its weekday (test scenarios).
    `takeover`: (NODE, control variable) setpoints the agent's actions own (takeover.taken_setpoints).
    `ventilation`: the outdoor air on demand (buildings/idf/ventilation.py)."""
    text = source.read_text(encoding="latin-1")
    objects = idf_objects(text)
    kinds = {o.kind.lower() for o in objects}
    by_kind: dict[str, list[IdfObject]] = {}
    for o in objects:
        by_kind.setdefault(o.kind.lower(), []).append(o)
    periods = by_kind.get("runperiod", [])
    control = by_kind.get("simulationcontrol", [None])[0]
    replace: dict[int, tuple[int, str]] = {}  # start -> (end, new text)
    for k, o in enumerate(periods):  # exactly one run period, the episode's, where the model's first one was
        replace[o.start] = (
            _line_end(text, o.end),
            _run_period(o, run_days, start_day, weekday).lstrip() + "\n" if k == 0 else "",
        )
    if control is not None:
        replace[control.start] = (control.end, _set_fields(text, control, _WEATHER_YEAR))
    files = by_kind.get("outputcontrol:files", [])
    csv = energyplus_csv or bool(outputs)  # read-backs are read from EnergyPlus's CSV
    if files and files[0].fields and (files[0].fields[0].lower() == "yes") != csv:
        replace[files[0].start] = (files[0].end, _set_fields(text, files[0], {0: "Yes" if csv else "No"}))
    managers, report = plan_takeover(objects, takeover)
    by_start = {o.start: o for o in objects}
    demand = plan_ventilation(text, objects) if ventilation else DemandVentilation()
    for start, values in demand.set_fields:
        replace[start] = (by_start[start].end, _set_fields(text, by_start[start], values))
    lists = []
    for start, (end, keep) in managers.items():
        new, nodelist = rewrite(text, by_start[start], keep, _set_fields)
        replace[start] = (end, new)
        lists += [nodelist] if nodelist else []
    out, pos = [], 0
    for start in sorted(replace):
        end, new = replace[start]
        out += [text[pos:start], new]
        pos = end
    out.append(text[pos:])
    added = [] if periods else [_run_period(None, run_days, start_day, weekday)]
    if control is None:
        added.append(_simulation_control(kinds))
    added += [_object("Output:Variable", [key, variable, "Timestep"], "read back by parallel-eplus")
              for key, variable in outputs]  # fmt: skip
    if outputs and not files:
        added.append(_object("OutputControl:Files", ["Yes"], "EnergyPlus's CSV for the read-backs"))
    added += lists
    added += [_object(kind, fields, "outdoor air on demand, set by parallel-eplus")
              for kind, fields in demand.objects()]  # fmt: skip
    target.write_text("".join(out) + "".join(f"\n\n{a}\n" for a in added), encoding="latin-1")
    return dataclasses.replace(report, ventilation=demand.notes) if ventilation else report


def takeover_report(idf: Path, actions) -> Takeover:
    """What the prepared copy of `idf` takes from its setpoint managers for `actions`, without writing the copy."""
    return plan_takeover(idf_objects(idf.read_text(encoding="latin-1")), taken_setpoints(actions))[1]
