"""One episode's directory, its record of every step, and the paper's summary statistics."""

from __future__ import annotations

import datetime as dt
import json
import os
import re
import shutil
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from parallel_eplus.buildings.datacenter import SENSOR_NAMES
from parallel_eplus.buildings.scoring.comfort import APPLIES, Comfort
from parallel_eplus.buildings.scoring.kpis import floor_area, per_area

STEPS_FILE = "steps.parquet"  # binary: a year writes in ~0.1 s where CSV takes ~0.8 s
SUMMARY_FILE = "summary.json"
MODEL_FILE = "model.idf"
FAILURE_FILE = "failure.txt"  # beside a failed episode's files: the error, and a mark that keeps them
REWARD_PARTS = ("reward_comfort", "reward_band", "reward_power")
STEP_FLAGS = (APPLIES,)  # after the reward parts in each step row


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


def bridge_counters(episode_dir: str | Path) -> dict[str, float]:
    """What the C bridge reported about an episode's steps (the `bridge ...` line eplus_callback.py prints in its
    energyplus.log): stepping_s, waited_s, ahead_s, exchanges, callback counts. Empty where the Python bridge ran."""
    path = Path(episode_dir) / "energyplus.log"
    for line in path.read_text(errors="replace").splitlines() if path.is_file() else ():
        if line.startswith("bridge "):
            fields = line.split()[1:]
            return {fields[i]: float(fields[i + 1]) for i in range(0, len(fields), 2)}
    return {}


class StepRecorder:
    """Rows of (time, observation, action, reward, components), one list per step until the episode ends.

    Appending a row is the cheapest bookkeeping a step can do (writing it into a numpy array cost ~1 us a
    step on the path between EnergyPlus's observation and its next action); the table is built once, at
    the end, while EnergyPlus finishes its own files. Rows are tuples of floats, which Python's garbage
    collector stops tracking, so a year of them adds nothing to its passes."""

    def __init__(self, action_names: tuple[str, ...], sensor_names: tuple[str, ...] = SENSOR_NAMES):
        self.columns = (*sensor_names, *action_names, "reward", *REWARD_PARTS, *STEP_FLAGS)
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


def reported_rows(table: pd.DataFrame, columns: Sequence[str]) -> pd.DataFrame:
    """The rows of an eplusout.csv `table` where any of `columns` (outputs reported every step) was reported: a
    model's own outputs at the HVAC's `Detailed` frequency add rows between the steps, where the step's outputs
    are blank (the DOE medium office: 65,925 rows for 52,560 steps)."""
    return table[table[list(columns)].notna().any(axis=1)].reset_index(drop=True)


def read_steps(episode_dir: str | Path) -> pd.DataFrame:
    """An episode's step table, as written at its end."""
    return pd.read_parquet(Path(episode_dir) / STEPS_FILE)


def summarize(steps: pd.DataFrame, comfort: Comfort | None = None) -> dict[str, float]:
    """The paper's episode statistics (Section 5) and BOPTEST's figures, for any building (`comfort`: its reward
    signals; None: the data center's): power in kW, zone temperatures and the share in band where the band
    applies, discomfort (K·h per zone), energy (kWh, every fuel) and peak electric power (scoring/comfort.py)."""
    out: dict[str, float] = {"steps": float(len(steps))}
    if steps.empty:
        return out
    if comfort is None:
        from parallel_eplus.buildings.building import load_building

        comfort = load_building().comfort
    out["reward_mean"] = float(steps["reward"].mean())
    out["power_kw"] = float(steps[comfort.power].mean() / 1000)
    for col in ("it_power_w", "hvac_power_w"):  # the data center's power split, where a building has it
        if col in steps:
            out[col.replace("_w", "_kw")] = float(steps[col].mean() / 1000)
    out.update(comfort.summarize(steps))
    return out


def write_records(
    episode_dir: Path,
    steps: pd.DataFrame,
    extra: dict,
    comfort: Comfort | None = None,
    scored: pd.DataFrame | None = None,
    table: bool = True,
    area_m2: float | None = None,
) -> dict:
    """Write the step table and summary.json; returns the summary. Per-m² figures divide by the spec's floor area,
    else `area_m2` (the model's, from an earlier episode), else the model's own (its eplusout.eio, written before the
    first step). `scored`: the steps the figures count (a test period without its warm-up); None: all.
    `table=False`: the summary only (an episode about to be pruned to its summary)."""
    if table:
        steps.to_parquet(episode_dir / STEPS_FILE, index=False)
    summary = {**extra, **summarize(steps if scored is None else scored, comfort)}
    if comfort is not None and comfort.kpis is not None:
        area = comfort.kpis.floor_area_m2 or area_m2 or floor_area(episode_dir / "eplusout.eio")
        summary |= per_area(summary, area)
    (episode_dir / SUMMARY_FILE).write_text(json.dumps(summary, indent=2, default=str))
    return summary


def record_failure(episode_dir: Path | None, error: BaseException) -> None:
    """Write why an episode failed into its directory, which pruning then keeps whole: the evidence (EnergyPlus's
    error file, the model, the steps up to the failure) outlives the restart that follows."""
    if episode_dir is not None and Path(episode_dir).is_dir():
        (Path(episode_dir) / FAILURE_FILE).write_text(f"{error}\n")


def prune_episodes(dirs: list[Path], keep: int | None) -> list[Path]:
    """Of one env's own episode directories (oldest first), keep the newest `keep` whole, and every failed one;
    older ones keep only their summary. Returns those still whole, to pass next time.

    Only the caller's own: another env writing to the same folder keeps its episodes (one may be running)."""
    if keep is None:
        return []
    whole = [d for d in dirs if d.is_dir() and not (d / FAILURE_FILE).is_file()]
    cut = whole[: max(len(whole) - keep, 0)]
    for d in cut:
        for f in d.iterdir():
            if f.name != SUMMARY_FILE:
                shutil.rmtree(f) if f.is_dir() else f.unlink()
    return whole[len(cut) :]


_EPISODE_DIR = re.compile(r"episode-(\d{6,})-")


def last_episode_number(output_dir: Path) -> int:
    """The highest number among the `episode-NNNNNN-*` directories in `output_dir` (0 if none)."""
    try:
        names = os.listdir(output_dir)
    except FileNotFoundError:
        return 0
    return max((int(m.group(1)) for n in names if (m := _EPISODE_DIR.match(n))), default=0)


def claim_episode_dir(output_dir: Path, label: str, number: int = 1) -> tuple[Path, int]:
    """Make and own `episode-NNNNNN-LABEL` in `output_dir`: (its path, its number).

    The number is at least `number` and above every episode number in the folder, so numbers sort in the order
    the episodes began and a resumed run continues them. Whoever's `mkdir` succeeds owns the directory: envs,
    vector envs and whole runs sharing one folder (RLlib hands every env runner the same `output_dir`) never
    write into each other's episodes, and nothing already there is replaced.
    """
    output_dir.mkdir(parents=True, exist_ok=True)
    while True:
        number = max(number, last_episode_number(output_dir) + 1)
        path = output_dir / f"episode-{number:06d}-{label}"
        try:
            path.mkdir()
            return path, number
        except FileExistsError:  # another env took it between the scan and the mkdir
            number += 1


@dataclass(frozen=True)
class EpisodePlan:
    """What one episode runs, decided before its process starts: its weather (the rotation's pick, or the
    reset's `weather_index`) and the reset's seed and options it was planned for. Everything drawn per episode
    (a perturbed weather file, say) belongs here, drawn when the plan is made, so a prepared episode and a cold
    one with the same plan are the same episode."""

    weather_index: int
    weather: str
    epw: Path
    seed: int | None = None
    options: tuple = field(default=())  # the reset's options as sorted (key, value) pairs
    start_day: int | None = None  # the run's first day of the year (`random_start`); None: the config's

    @staticmethod
    def options_key(options: dict | None) -> tuple:
        return tuple(sorted((options or {}).items(), key=lambda kv: kv[0]))
