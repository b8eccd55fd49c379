"""A candidate scored as every other one is: `evaluate --scenario` on each test period, on the training and the held-out
weathers, the periods' days handed over (periods.py); each period's evaluation kept in eval/<candidate>/<period>/ (an
interrupted one resumes with `evaluate --resume`), then every candidate's rows gathered in results/<period>.csv, the
files the report is read from."""

from __future__ import annotations

import json
import logging
import shutil
from pathlib import Path

import pandas as pd

from parallel_eplus.optimize.candidates import Candidate
from parallel_eplus.optimize.command import failure, run_command, stage_bar
from parallel_eplus.optimize.folders import BuildingFolder
from parallel_eplus.optimize.periods import EVALUATE_AS, weather_labels, write_for_evaluation
from parallel_eplus.optimize.settings import OptimizeSettings

log = logging.getLogger(__name__)

DONE_FILE = "scored.json"  # beside an evaluation's results.csv once its rows are read


def _episodes_done(out: Path) -> int:
    return sum(1 for _ in (out / "episodes").rglob("summary.json")) if (out / "episodes").is_dir() else 0


def score(folder: BuildingFolder, candidate: Candidate, periods: dict, settings: OptimizeSettings,
          show: bool) -> dict:  # fmt: skip
    """Evaluate `candidate` on every period not yet scored; returns the stage's fields (state done with the episodes
    that failed, or failed with why)."""
    todo = [name for name in periods if not (folder.evaluation(candidate.key, name) / DONE_FILE).is_file()]
    total = sum(len(periods[name]) for name in periods)
    done_before = total - sum(len(periods[name]) for name in todo)
    bar = stage_bar(f"{folder.name}: {candidate.label}", show, total, "episode")
    bar.update(done_before)
    seconds, failed = 0.0, []
    try:
        for name in todo:
            out = folder.evaluation(candidate.key, name)
            write_for_evaluation(periods, name, out)
            weathers = list(periods[name])
            args = ["evaluate", "--building", str(candidate.spec), *candidate.args, "--scenario",
                    EVALUATE_AS.get(name, name), "--weathers", ",".join(weathers), "--workers", str(settings.workers),
                    "--out", str(out), "--quiet"]  # fmt: skip
            if (out / "episodes").is_dir():
                args.append("--resume")  # the episodes an interrupted evaluation finished stay
            before, n = bar.n, len(weathers)

            def progress(out: Path = out, before: int = before, n: int = n) -> tuple[int, int]:
                return before + min(_episodes_done(out), n), total

            outcome = run_command(args, folder.logs / f"eval-{candidate.key}.log", folder.root,
                                  f"{candidate.label} {name}", show=show, bar=bar, progress=progress)  # fmt: skip
            seconds += outcome.seconds
            results = out / "results.csv"
            rows = pd.read_csv(results) if results.is_file() else pd.DataFrame()
            if outcome.returncode not in (0, 1) or rows.empty:
                return {"state": "failed", "error": f"evaluate on {name}: {failure(outcome.log)}", "seconds": seconds}
            mine = rows[rows.controller == candidate.controller] if "controller" in rows else rows.iloc[:0]
            missing = sorted(set(weathers) - set(mine.weather))
            failed += [f"{name} {w}" for w in missing]
            if missing:
                log.warning("%s: %s did not finish on %s %s (see %s)", folder.name, candidate.label, name,
                            ", ".join(missing), out / "results.md")  # fmt: skip
            (out / DONE_FILE).write_text(json.dumps({"missing": missing}) + "\n")
            bar.n = before + len(weathers)
            bar.refresh()
    finally:
        bar.close()
    return {"state": "done", "failed_episodes": failed, "seconds": round(seconds, 1)}


def forget(folder: BuildingFolder, key: str) -> None:
    """A candidate's evaluations dropped (a learned controller trained further is scored again)."""
    shutil.rmtree(folder.root / "eval" / key, ignore_errors=True)


def gather(folder: BuildingFolder, candidates: list[Candidate], periods: dict, settings: OptimizeSettings) -> Path:
    """results/<period>.csv: every scored candidate's rows of evaluate's results.csv, with its key, its label, the
    period and whether the weather is held out; returns the folder."""
    held_out = set(weather_labels(settings.held_out))
    folder.results.mkdir(parents=True, exist_ok=True)
    for name in periods:
        frames = []
        for c in candidates:
            path = folder.evaluation(c.key, name) / "results.csv"
            if not (folder.evaluation(c.key, name) / DONE_FILE).is_file() or not path.is_file():
                continue
            rows = pd.read_csv(path)
            rows = rows[rows.controller == c.controller].copy()
            rows.insert(0, "candidate", c.key)
            rows.insert(1, "label", c.label)
            rows.insert(2, "period", name)
            rows.insert(3, "held_out", rows.weather.isin(held_out))
            frames.append(rows)
        if frames:
            pd.concat(frames, ignore_index=True).to_csv(folder.results / f"{name}.csv", index=False)
    return folder.results
