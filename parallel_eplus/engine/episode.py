"""One episode's directory, its record of every step, and the paper's summary statistics."""

from __future__ import annotations

import datetime as dt
import json
import os
import re
import shutil
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import pandas as pd

from parallel_eplus.buildings.model import COMFORT_BAND_C, SENSOR_NAMES, ZONE_TEMP_NAMES

STEPS_FILE = "steps.parquet"  # binary: a year writes in ~0.1 s where CSV takes ~0.8 s
SUMMARY_FILE = "summary.json"
MODEL_FILE = "model.idf"
FAILURE_FILE = "failure.txt"  # beside a failed episode's files: the error, and a mark that keeps them
REWARD_PARTS = ("reward_comfort", "reward_band", "reward_power")

_RUN_PERIOD = re.compile(r"^[ \t]*RunPeriod,[^;]*;", re.MULTILINE | re.IGNORECASE)
_TIMESTEP = re.compile(r"^[ \t]*Timestep,[^;]*;", re.MULTILINE | re.IGNORECASE)
# OutputControl:Files's first field, "Output CSV" (comments may sit between the object's name and it)
_OUTPUT_CSV = re.compile(r"^([ \t]*OutputControl:Files\s*,(?:[ \t]*!.*)?\s*)Yes\b", re.MULTILINE | re.IGNORECASE)


def run_period_end(run_days: int) -> tuple[int, int]:
    """(month, day) of the last day of a run starting Jan 1; 2013 stands in for any non-leap year."""
    if not 1 <= run_days <= 365:
        raise ValueError(f"run_days must be within 1..365, got {run_days}")
    end = dt.date(2013, 1, 1) + dt.timedelta(days=run_days - 1)
    return end.month, end.day


def write_episode_idf(source: Path, target: Path, run_days: int, energyplus_csv: bool = True) -> None:
    """Copy the model with one run period of `run_days` from Jan 1, keeping the model's own timestep.

    `energyplus_csv=False` turns off EnergyPlus's own CSV where the model asks for it: EnergyPlus holds
    every reported value in memory until the run ends to write it (for the data center, a year costs
    55 MB and 1.4 s), and our step records (steps.parquet) already have what training needs.
    """
    from parallel_eplus.buildings.building import timesteps_per_hour

    per_hour = timesteps_per_hour(source)
    text = source.read_text(encoding="latin-1")
    if not _RUN_PERIOD.search(text):
        raise ValueError(f"{source} has no RunPeriod object to set the episode length in")
    month, day = run_period_end(run_days)
    run_period = (
        "  RunPeriod,\n    Episode,\n    1,\n    1,\n    ,\n"
        f"    {month},\n    {day},\n    ,\n"
        "    Tuesday,\n    Yes,\n    Yes,\n    No,\n    Yes,\n    Yes;  ! set by parallel-eplus"
    )
    text = _RUN_PERIOD.sub("", text)  # exactly one run period: the episode's
    text = _TIMESTEP.sub("", text)
    if not energyplus_csv:
        text = _OUTPUT_CSV.sub(r"\1No", text, count=1)
    text += f"\n{run_period}\n\n  Timestep,{per_hour};\n"
    target.write_text(text, encoding="latin-1")


def link_or_copy(source: Path, target: Path) -> None:
    """Weather files are never modified: a hard link records which one ran at no disk cost."""
    try:
        os.link(source, target)
    except OSError:
        shutil.copyfile(source, target)


def err_tail(episode_dir: Path | None, lines: int = 12) -> str:
    """Last lines of EnergyPlus's error file and of the EnergyPlus process's own log."""
    if episode_dir is None:
        return ""
    parts = []
    for name in ("eplusout.err", "energyplus.log"):
        path = episode_dir / name
        if path.is_file():
            text = path.read_text(errors="replace").strip().splitlines()
            if text:
                parts.append(f"[{name}]\n" + "\n".join(text[-lines:]))
    return "\n".join(parts)


class StepRecorder:
    """Rows of (time, observation, action, reward, components), one list per step until the episode ends.

    Appending a row is the cheapest bookkeeping a step can do (writing it into a numpy array cost ~1 us a
    step on the path between EnergyPlus's observation and its next action); the table is built once, at
    the end, while EnergyPlus finishes its own files. Rows are tuples of floats, which Python's garbage
    collector stops tracking, so a year of them adds nothing to its passes."""

    def __init__(self, action_names: tuple[str, ...], sensor_names: tuple[str, ...] = SENSOR_NAMES):
        self.columns = (*sensor_names, *action_names, "reward", *REWARD_PARTS)
        self.rows: list[Sequence[float]] = []
        self.times: list[dt.datetime] = []

    @property
    def n(self) -> int:
        return len(self.rows)

    def add(self, time: dt.datetime, row: Sequence[float]) -> None:
        self.rows.append(row)
        self.times.append(time)

    def frame(self) -> pd.DataFrame:
        values = np.array(self.rows, dtype=float).reshape(len(self.rows), len(self.columns))
        df = pd.DataFrame(values, columns=list(self.columns))
        df.insert(0, "time", pd.to_datetime(self.times))
        return df


def read_steps(episode_dir: str | Path) -> pd.DataFrame:
    """An episode's step table, as written at its end."""
    return pd.read_parquet(Path(episode_dir) / STEPS_FILE)


def summarize(
    steps: pd.DataFrame,
    temperatures: tuple[str, ...] = ZONE_TEMP_NAMES,
    power: str = "power_w",
    band: tuple[float, float] = COMFORT_BAND_C,
) -> dict[str, float]:
    """The paper's episode statistics (Section 5): power in kW, zone temperatures, share in the band.

    Any building's: `temperatures`, `power` and `band` are its spec's reward signals."""
    out: dict[str, float] = {"steps": float(len(steps))}
    if steps.empty:
        return out
    out["reward_mean"] = float(steps["reward"].mean())
    out["power_kw"] = float(steps[power].mean() / 1000)
    for col in ("it_power_w", "hvac_power_w"):  # the data center's power split, where a building has it
        if col in steps:
            out[col.replace("_w", "_kw")] = float(steps[col].mean() / 1000)
    low, high = band
    in_band = []
    for col in temperatures:
        zone = col.removesuffix("_temp_c")
        t = steps[col]
        out[f"{zone}_temp_mean"] = float(t.mean())
        out[f"{zone}_temp_std"] = float(t.std(ddof=0))
        out[f"{zone}_temp_min"] = float(t.min())
        out[f"{zone}_temp_max"] = float(t.max())
        ok = t.between(low, high)
        out[f"{zone}_in_band_pct"] = float(100 * ok.mean())
        in_band.append(ok.to_numpy())
    out["in_band_pct"] = float(100 * np.concatenate(in_band).mean())
    return out


def write_records(episode_dir: Path, steps: pd.DataFrame, extra: dict, **signals) -> dict:
    """Write the step table and summary.json; returns the summary. `signals`: `summarize`'s keywords."""
    steps.to_parquet(episode_dir / STEPS_FILE, index=False)
    summary = {**extra, **summarize(steps, **signals)}
    (episode_dir / SUMMARY_FILE).write_text(json.dumps(summary, indent=2, default=str))
    return summary


def record_failure(episode_dir: Path | None, error: BaseException) -> None:
    """Write why an episode failed into its directory, which pruning then keeps whole: the evidence (EnergyPlus's
    error file, the model, the steps up to the failure) outlives the restart that follows."""
    if episode_dir is not None and Path(episode_dir).is_dir():
        (Path(episode_dir) / FAILURE_FILE).write_text(f"{error}\n")


def prune_episodes(output_dir: Path, keep: int | None) -> None:
    """Keep the newest `keep` episode directories whole, and every failed one; older ones keep only their summary."""
    if keep is None:
        return
    dirs = sorted(p for p in output_dir.glob("episode-*") if p.is_dir() and not (p / FAILURE_FILE).is_file())
    full = [d for d in dirs if any(f.name != SUMMARY_FILE for f in d.iterdir())]
    for d in full[: max(len(full) - keep, 0)]:
        for f in d.iterdir():
            if f.name != SUMMARY_FILE:
                shutil.rmtree(f) if f.is_dir() else f.unlink()
