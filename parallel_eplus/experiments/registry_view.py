"""What `parallel-eplus runs` prints: the table of runs, and one run's progress and settings."""

from __future__ import annotations

import json
import os
from pathlib import Path

from parallel_eplus.runs.registry import CONFIG_FILE, RunInfo

COLUMNS = (
    "NAME",
    "STATE",
    "PROCESS",
    "STEPS",
    "EPISODES",
    "WALL",
    "CHECKPOINT",
    "EVAL (step: in band, energy)",
    "LATEST (in band, power)",
)


def duration(seconds: float | None) -> str:
    """45s, 6m25s, 2h05m, 3d04h."""
    if seconds is None:
        return "-"
    s = int(seconds)
    if s < 60:
        return f"{s}s"
    if s < 3600:
        return f"{s // 60}m{s % 60:02d}s"
    if s < 86400:
        return f"{s // 3600}h{s % 3600 // 60:02d}m"
    return f"{s // 86400}d{s % 86400 // 3600:02d}h"


def _latest(info: RunInfo) -> str:
    parts = []
    for weather, row in info.latest.items():
        band, power = row.get("in_band_pct"), row.get("power_kw")
        parts.append(f"{weather} {band:.1f}% {power:.0f}kW" if band == band and power == power else weather)
    return ", ".join(parts) or "-"


def evaluation(e: dict | None) -> str:
    """The newest evaluation, short: `4096: 99.1% -12.3%` (in band; energy against the built-in controller)."""
    if not e:
        return "-"
    band, energy = e.get("in_band_pct", float("nan")), e.get("energy_change_pct", float("nan"))
    return f"{int(e['timesteps'])}: {band:.1f}% {energy:+.1f}%" + (" met" if e.get("target_met") else "")


def _steps(info: RunInfo) -> str:
    return f"{info.steps}/{info.planned}" if info.planned else str(info.steps)


def table(runs: list[RunInfo]) -> str:
    """One line per run, columns aligned."""
    rows = [COLUMNS] + [
        (r.name, r.state, r.process or "-", _steps(r), str(r.episodes), duration(r.wall_s),
         r.checkpoint.name if r.checkpoint else "-", evaluation(r.evaluation), _latest(r))
        for r in runs
    ]  # fmt: skip
    widths = [max(len(row[i]) for row in rows) for i in range(len(COLUMNS) - 1)]
    return "\n".join("  ".join([*(c.ljust(w) for c, w in zip(row, widths, strict=False)), row[-1]]) for row in rows)


def _shown(path: Path) -> str:
    rel = os.path.relpath(path)
    return path.as_posix() if rel.startswith("..") else rel


def details(info: RunInfo) -> str:
    """One run: state and process, progress, the latest episode of each weather, then its settings."""
    status = info.status or {}
    share = f" ({100 * info.steps / info.planned:.0f} %)" if info.planned else ""
    lines = [
        f"run         {info.name}  ({_shown(info.path)})",
        f"state       {info.state}" + (f": {info.process}" if info.process else ""),
        *([f"process     {status['pid']}@{status['host']}"] if status and info.state != "running" else []),
        f"steps       {info.steps} of {info.planned or '?'}{share}",
        f"episodes    {info.episodes}",
        f"wall time   {duration(info.wall_s)}"
        + (f" (started {status['first_started']}, last update {status['updated']})" if status else ""),
        f"checkpoint  {_shown(info.checkpoint) if info.checkpoint else '-'}",
    ]
    if info.note:
        lines.append(f"note        {info.note}")
    if info.evaluation:
        lines.append(f"evaluation  {evaluation(info.evaluation)} (newest; evaluations.csv, best/model.zip)")
    if info.target:
        t = info.target
        lines.append(f"target      {t['target']}: first met at step {t['timesteps']} after {duration(t['wall_s'])}")
    if info.latest:
        lines += ["", "latest episode of each weather:", "  weather  episodes  at step  in band  power     reward/step"]
        for weather, row in info.latest.items():
            lines.append(
                f"  {weather:<7}  {row['count']:>8}  {row.get('timesteps', 0):>7.0f}  {row.get('in_band_pct', 0):6.2f}%"
                f"  {row.get('power_kw', 0):6.1f} kW  {row.get('reward_mean', float('nan')):11.3f}"
            )
    config = json.loads((info.path / CONFIG_FILE).read_text())
    lines += ["", f"config ({_shown(info.path / CONFIG_FILE)}):"]
    for key, value in config.items():
        if isinstance(value, dict):
            value = ", ".join(f"{k}={v}" for k, v in value.items())
        elif isinstance(value, list):
            value = ",".join(map(str, value))
        lines.append(f"  {key:<18} {value}")
    return "\n".join(lines)
