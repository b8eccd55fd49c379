"""BOPTEST's test scenarios as evaluation presets: two weeks around a peak or typical heating or cooling day.

BOPTEST (`data/find_days.py` of ibpsa/project1-boptest) picks each test case's days from a year of its baseline
controller's heating and cooling loads, resampled to 15-minute means:
- the peak day holds the year's highest 15-minute load, among days 14 to 358 (a two-week period and its one-week
  warm-up must fit in the year);
- the typical day is the day whose daily peak is the highest at or below the median daily peak, over the days
  with any load (above 1 W);
- a scenario is the two weeks centred on its day (days d-7 to d+6), after a one-week warm-up.
Here the loads are the zones' own (`Zone Air System Sensible Heating/Cooling Rate`, summed over the zones) under
the building's built-in controls, on each weather, so each weather gets its own periods. The warm-up runs under
the controller being evaluated (BOPTEST warms up under the test case's baseline) and is left out of the figures.
"""

from __future__ import annotations

import datetime as dt
import json
import logging
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import pandas as pd

from parallel_eplus.engine.episode import reported_rows

if TYPE_CHECKING:
    from parallel_eplus.buildings.building import Building

log = logging.getLogger(__name__)

SCENARIOS = ("year", "peak_heat", "typical_heat", "peak_cool", "typical_cool")
PERIOD_DAYS = 14
WARMUP_DAYS = 7
LOADS = (("*", "Zone Air System Sensible Heating Rate"), ("*", "Zone Air System Sensible Cooling Rate"))
PERIODS_FILE = "scenarios.json"


@dataclass(frozen=True)
class Period:
    """A scenario on one weather: its day, and the run that scores it (warm-up, then the two weeks)."""

    scenario: str
    day: int  # BOPTEST's day: 0 is January 1
    start_day: int  # the run's first day of the year (1: January 1): the warm-up's first
    weekday: str  # that day's weekday in the year run, so the schedules fall as they did
    run_days: int = PERIOD_DAYS + WARMUP_DAYS
    warmup_days: int = WARMUP_DAYS

    @property
    def first_scored(self) -> dt.date:
        return dt.date(2013, 1, 1) + dt.timedelta(days=self.start_day - 1 + self.warmup_days)


def find_days(heat: pd.Series, cool: pd.Series) -> dict[str, int]:
    """BOPTEST's peak and typical heating and cooling days (0: the series' first day) from load series in W with a
    time index starting on January 1. A load that is never above 1 W has no days."""
    days: dict[str, int] = {}
    for kind, load in (("heat", heat), ("cool", cool)):
        load = load.resample("15min").mean().dropna()
        t0 = load.index[0].normalize()
        day = pd.Series((load.index - t0).days, index=load.index)
        available = load[(day >= 14) & (day <= 365 - 7)]
        if available.empty or available.max() <= 1.0:
            continue
        days[f"peak_{kind}"] = int(day[available.idxmax()])
        daily = load.groupby(day.to_numpy()).max()
        median = daily[daily > 1.0].median()
        fit = daily[(daily <= median) & (daily.index >= 14) & (daily.index <= 365 - 7)]
        days[f"typical_{kind}"] = int(fit.sort_values(ascending=False).index[0])
    return days


def period(scenario: str, day: int, year_start: dt.datetime) -> Period:
    """The run for `scenario` around `day`: from day-14 (warm-up) to day+6 (BOPTEST's two weeks centred on it)."""
    start = day - PERIOD_DAYS // 2 - WARMUP_DAYS  # 0-based
    weekday = (year_start + dt.timedelta(days=start)).strftime("%A")
    return Period(scenario, day, start + 1, weekday)


def loads(episode_dir: Path, partial: bool = False) -> tuple[pd.Series, pd.Series]:
    """The zones' summed heating and cooling loads (W) of a year run with `LOADS` reported, on its step times;
    `partial`: a run that failed, up to its last step."""
    table = pd.read_csv(episode_dir / "eplusout.csv")
    pick = lambda name: [c for c in table.columns if name.upper() in c.upper()]  # noqa: E731
    table = reported_rows(table, pick(LOADS[0][1]) + pick(LOADS[1][1]))
    steps = pd.read_parquet(episode_dir / "steps.parquet", columns=["time"])
    if len(table) != len(steps) and not partial:
        raise ValueError(f"{episode_dir}: {len(table)} rows in eplusout.csv for {len(steps)} steps")
    n = min(len(table), len(steps))  # a failed run: its steps up to the failure
    table, steps = table.iloc[:n], steps.iloc[:n]
    index = pd.DatetimeIndex(steps["time"]) - pd.Timedelta(seconds=1)  # each step's load in its own day
    heat = table[pick(LOADS[0][1])].sum(axis=1).to_numpy(float)
    cool = table[pick(LOADS[1][1])].sum(axis=1).to_numpy(float)
    return pd.Series(heat, index=index), pd.Series(cool, index=index)


def _loads_of(episode_dir: Path, weather: str, failed: bool, error: str | None) -> tuple[pd.Series, pd.Series]:
    """A year's loads; where the built-in controls failed in it (the CRAC's on Golden's December cold snap), the
    days up to a week before the failure (its run-up is no load of the building's: the CRAC's zone passed 200 °C,
    which would be its peak cooling day), if that leaves four weeks."""
    if not failed:
        return loads(episode_dir)
    try:
        heat, cool = loads(episode_dir, partial=True)
    except (OSError, ValueError, KeyError):
        heat = cool = pd.Series(dtype=float)
    if len(heat):
        cut = heat.index[-1].normalize() - pd.Timedelta(days=7)
        heat, cool = heat[heat.index < cut], cool[cool.index < cut]
    if len(heat) == 0 or (heat.index[-1] - heat.index[0]).days < 28:
        raise ValueError(f"{weather}: the built-in controls failed before BOPTEST's days could be found ({error}); "
                         f"see {episode_dir}")  # fmt: skip
    log.warning("%s: the built-in controls failed (%s); BOPTEST's days are found up to %s", weather, error,
                heat.index[-1].date())  # fmt: skip
    return heat, cool


def find_periods(
    scenario: str,
    weathers: list[str],
    building: str | Building | None,
    out_dir: Path,
    workers: int = 1,
    progress: bool = True,
) -> dict[str, Period]:
    """Each weather's period for `scenario`, from a year of the built-in controls (run once per weather and kept in
    `out_dir/scenarios.json` with every scenario's day, so other scenarios reuse it). `building`: a spec, or the
    `Building` the command resolved (None: the data center)."""
    from parallel_eplus.buildings.weather.files import weather_label
    from parallel_eplus.evaluation.controllers import BASELINE_LABEL, Controller
    from parallel_eplus.evaluation.sweep import run_sweep

    path = out_dir / PERIODS_FILE
    known = json.loads(path.read_text()) if path.is_file() else {}
    todo = [w for w in weathers if weather_label(w) not in known]
    if todo:
        log.info("finding BOPTEST's days: a year of the built-in controls on %s", ", ".join(todo))
        df = run_sweep(
            [Controller(BASELINE_LABEL, "baseline")], todo, 365, workers, out_dir / "scenario-loads", None, progress,
            building, extra_outputs=LOADS, keep_going=True,
        )  # fmt: skip
        runs = [(row, False) for _, row in df.iterrows()] + [(f, True) for f in df.attrs["failures"]]
        for row, failed in runs:
            heat, cool = _loads_of(Path(row["episode_dir"]), row["weather"], failed, row.get("error"))
            year_start = heat.index[0].normalize().to_pydatetime()
            days = find_days(heat, cool)
            known[row["weather"]] = {
                s: asdict(period(s, d, year_start)) | {"first_scored": str(period(s, d, year_start).first_scored)}
                for s, d in days.items()
            }
        out_dir.mkdir(parents=True, exist_ok=True)
        path.write_text(json.dumps(known, indent=2))
    out = {}
    for w in weathers:
        found = dict(known.get(weather_label(w), {}).get(scenario) or {})
        if not found:
            raise ValueError(f"{weather_label(w)}: the built-in controls have no {scenario.split('_')[1]}ing load")
        found.pop("first_scored", None)
        out[weather_label(w)] = Period(**found)
    return out


def periods_markdown(periods: dict[str, Period]) -> str:
    """The dates a scenario's figures count, per weather, for the end of results.md."""
    lines = ["", "## Test periods (BOPTEST's scenarios, evaluation/scenarios.py)", ""]
    lines += ["| Weather | scenario | day | scored from | scored to | warm-up from |", "|---|---|---|---|---|---|"]
    for w, p in periods.items():
        first = p.first_scored
        last = first + dt.timedelta(days=PERIOD_DAYS - 1)
        warm = first - dt.timedelta(days=p.warmup_days)
        day = dt.date(2013, 1, 1) + dt.timedelta(days=p.day)
        lines.append(f"| {w} | {p.scenario} | {day:%b %d} | {first:%b %d} | {last:%b %d} | {warm:%b %d} |")
    return "\n".join(lines) + "\n"
