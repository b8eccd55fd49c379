"""BOPTEST's test periods, found once per building and weather (a year of the building's own controls each, the costly
part of scoring) and handed to every evaluation as the `scenarios.json` `evaluate --scenario` reads from its `--out`
folder, so no candidate's evaluation searches the year again. `--scenario-days` shortens each period around its day;
`--quick` uses one fixed winter window instead (no year run: a smoke run, and the report says so)."""

from __future__ import annotations

import datetime as dt
import json
import logging
from pathlib import Path

from parallel_eplus.optimize.folders import BuildingFolder
from parallel_eplus.optimize.settings import (
    QUICK,
    QUICK_DAY,
    QUICK_SCORED_DAYS,
    QUICK_WARMUP_DAYS,
    SCENARIOS,
    OptimizeSettings,
)

log = logging.getLogger(__name__)

FOUND_FILE = "scenarios.json"  # find_periods' own file: BOPTEST's 14-day periods on every weather
PERIODS_FILE = "periods.json"  # what every evaluation scores: period name -> weather -> period
EVALUATE_AS = {QUICK: "peak_heat"}  # `--quick`'s window goes to `evaluate --scenario` under a name it takes
WEEKDAYS = ("Monday", "Tuesday", "Wednesday", "Thursday", "Friday", "Saturday", "Sunday")
WARMUP_DAYS = 7  # BOPTEST's


def weather_labels(weathers) -> list[str]:
    from parallel_eplus.buildings.weather.files import weather_label

    return [weather_label(w) for w in weathers]


def first_scored(p: dict) -> dt.date:
    return dt.date(2013, 1, 1) + dt.timedelta(days=p["start_day"] - 1 + p["warmup_days"])


def shortened(p: dict, days: int) -> dict:
    """A found period cut to `days` scored days around its day (from day - days // 2), after min(7, days) days of
    warm-up, on the weekday its new first day had in the year."""
    warm = min(WARMUP_DAYS, days)
    start_day = max(1, min(p["day"] - days // 2 - warm + 1, 365 - days - warm + 1))
    weekday = p.get("weekday")
    if weekday in WEEKDAYS:
        weekday = WEEKDAYS[(WEEKDAYS.index(weekday) + start_day - p["start_day"]) % 7]
    return p | {"start_day": start_day, "weekday": weekday, "run_days": days + warm, "warmup_days": warm}


def quick_period() -> dict:
    """`--quick`'s window: January 11-12 after a day's warm-up, on the model's own weekday for January 10."""
    return {"scenario": EVALUATE_AS[QUICK], "day": QUICK_DAY, "start_day": QUICK_DAY, "weekday": None,
            "run_days": QUICK_SCORED_DAYS + QUICK_WARMUP_DAYS, "warmup_days": QUICK_WARMUP_DAYS}  # fmt: skip


def find(folder: BuildingFolder, settings: OptimizeSettings, show: bool) -> dict:
    """Every period scored, per period name and weather (`periods.json`); found once, then read back."""
    path = folder.periods_dir / PERIODS_FILE
    if folder.done("periods") and path.is_file():
        return json.loads(path.read_text())
    weathers = weather_labels(settings.all_weathers)
    if settings.quick:
        periods = {QUICK: {w: quick_period() for w in weathers}}
        how = "`--quick`: one fixed window, January 11-12 after a day's warm-up (not BOPTEST's days)"
    else:
        found = _found(folder, settings, show)
        periods = {s: {w: found[w][s] for w in weathers if s in found.get(w, {})} for s in settings.scenarios}
        if settings.scenario_days < 14:
            periods = {s: {w: shortened(p, settings.scenario_days) for w, p in ps.items()} for s, ps in periods.items()}
        how = (f"BOPTEST's days from a year of the own controls on each weather; {settings.scenario_days} scored days "
               f"around each (warm-up {min(WARMUP_DAYS, settings.scenario_days)} days)")  # fmt: skip
    missing = {s: [w for w in weathers if w not in ps] for s, ps in periods.items()}
    missing = {s: ws for s, ws in missing.items() if ws}
    for s, ws in missing.items():
        log.warning("%s: no %s period on %s (the own controls have no such load there)", folder.name, s, ", ".join(ws))
    periods = {s: ps for s, ps in periods.items() if ps}
    if not periods:
        raise ValueError(f"{folder.name}: none of the test periods exists on any weather")
    folder.periods_dir.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(periods, indent=1) + "\n")
    folder.set_stage("periods", state="done", how=how, missing=missing)
    return periods


def _found(folder: BuildingFolder, settings: OptimizeSettings, show: bool) -> dict:
    """BOPTEST's days on every weather (evaluation/scenarios.py's `find_periods`, in process: a year of the own
    controls per weather, run once; its scenarios.json holds every scenario's day)."""
    from parallel_eplus.evaluation.scenarios import find_periods

    target = folder.periods_dir
    try:
        find_periods(SCENARIOS[0], list(settings.all_weathers), str(folder.spec), target, settings.workers, show)
    except ValueError as e:  # a weather without that scenario's load: the others are in the file all the same
        log.info("%s: %s", folder.name, e)
    found = json.loads((target / FOUND_FILE).read_text()) if (target / FOUND_FILE).is_file() else {}
    lost = [w for w in weather_labels(settings.all_weathers) if w not in found]
    if lost:
        raise ValueError(f"{folder.name}: the year of the own controls did not run on {', '.join(lost)}; see "
                         f"{target / 'scenario-loads'}")  # fmt: skip
    return found


def write_for_evaluation(periods: dict, name: str, out: Path) -> None:
    """`out/scenarios.json` as `evaluate --scenario` reads it: every weather's period `name`, under the scenario name
    it is evaluated as."""
    scenario = EVALUATE_AS.get(name, name)
    known = {w: {scenario: p | {"scenario": scenario, "first_scored": str(first_scored(p))}}
             for w, p in periods[name].items()}  # fmt: skip
    out.mkdir(parents=True, exist_ok=True)
    (out / FOUND_FILE).write_text(json.dumps(known, indent=2))


def dates(periods: dict) -> list[tuple[str, str, dt.date, dt.date]]:
    """(period, weather, first scored day, last) for the report."""
    out = []
    for name, ps in periods.items():
        for w, p in ps.items():
            first = first_scored(p)
            out.append((name, w, first, first + dt.timedelta(days=p["run_days"] - p["warmup_days"] - 1)))
    return out
