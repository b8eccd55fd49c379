"""The planner-year study's per-seed evaluations as one table per building and forecast, written by `evaluate`'s own
report code (results.csv, results.md with the seeds' intervals, seeds.csv, figures) into
results/model-based/<building>/year-planner[-<forecast>]/.

    .venv/bin/python studies/planner-year/merge.py WORK RESULTS
    .venv/bin/python studies/planner-year/merge.py --one FOLDER OUT    # FOLDER/seed*/results.csv into OUT
    .venv/bin/python studies/planner-year/merge.py --restore OUT FOLDER   # the reverse, for a new machine

`--restore` writes back each committed seed's FOLDER/seed<k>/results.csv from OUT/results.csv, so that on a new
machine the study resumes with the seeds still missing (and `--one` merges all of them again).

    .venv/bin/python studies/planner-year/merge.py --keep FOLDER OUT      # an unfinished seed's finished years

A year of the planner is half an hour of a core and a session ends mid-seed: `--keep` copies the summary.json of
each episode an unfinished seed finished into OUT/unfinished/ (a few kB each; committed), and `--restore` puts them
back where `evaluate --resume` finds them, so a new machine runs only the years still missing. `--one` drops a
seed's kept episodes once its results.csv is merged.
"""

from __future__ import annotations

import json
import logging
import shutil
import sys
from pathlib import Path

import pandas as pd

from parallel_eplus.engine.episode import FAILURE_FILE, SUMMARY_FILE
from parallel_eplus.evaluation.controllers import BASELINE_LABEL
from parallel_eplus.evaluation.results import write_results

log = logging.getLogger("planner-year")


def merge(folder: Path, out: Path) -> None:
    parts = sorted(folder.glob("seed*/results.csv"))
    if not parts:
        return
    frames = [pd.read_csv(p) for p in parts]
    df = pd.concat(frames, ignore_index=True)
    df = df[[c for c in df.columns if not c.endswith("_vs_builtin")]]
    baseline = df[df.controller == BASELINE_LABEL].drop_duplicates("weather")  # the same episode in every seed's
    df = pd.concat([baseline, df[df.controller != BASELINE_LABEL]], ignore_index=True)
    write_results(df, out)
    log.info("%s: %d seeds -> %s", folder, len(parts), out)
    for part in parts:  # a merged seed's kept episodes are in its results.csv now
        shutil.rmtree(out / UNFINISHED / part.parent.name, ignore_errors=True)


UNFINISHED = "unfinished"  # OUT/unfinished/seed<k>/...: the finished episodes of seeds not finished yet


def keep(folder: Path, out: Path) -> None:
    """Each unfinished seed's finished episodes (their summary.json, under the same relative path) into
    OUT/unfinished/."""
    for seed in sorted(p for p in folder.glob("seed*") if p.is_dir() and not (p / "results.csv").is_file()):
        for summary in sorted(seed.glob(f"episodes/**/episode-*/{SUMMARY_FILE}")):
            if (summary.parent / FAILURE_FILE).is_file() or json.loads(summary.read_text()).get("complete") is not True:
                continue
            kept = out / UNFINISHED / summary.relative_to(folder)
            kept.parent.mkdir(parents=True, exist_ok=True)
            shutil.copyfile(summary, kept)
            log.info("kept %s", kept)


def restore(out: Path, folder: Path) -> None:
    merged = out / "results.csv"  # none yet where no seed has finished
    df = pd.read_csv(merged) if merged.is_file() else pd.DataFrame(columns=["controller", "run"])
    baseline = df[df.controller == BASELINE_LABEL]
    for run, rows in df[df.controller != BASELINE_LABEL].groupby("run"):
        seed = folder / f"seed{str(run).rsplit('seed', 1)[1]}"
        seed.mkdir(parents=True, exist_ok=True)
        pd.concat([baseline, rows]).to_csv(seed / "results.csv", index=False)
        log.info("%s: %s restored", seed, run)
    for summary in sorted((out / UNFINISHED).glob(f"seed*/episodes/**/{SUMMARY_FILE}")):
        episode = folder / summary.relative_to(out / UNFINISHED)
        if not episode.is_file():
            episode.parent.mkdir(parents=True, exist_ok=True)
            shutil.copyfile(summary, episode)
            log.info("%s restored", episode.parent)


def main() -> None:
    logging.basicConfig(level=logging.INFO, format="%(message)s")
    if sys.argv[1] == "--restore":
        restore(Path(sys.argv[2]), Path(sys.argv[3]))
        return
    if sys.argv[1] == "--keep":
        keep(Path(sys.argv[2]), Path(sys.argv[3]))
        return
    if sys.argv[1] == "--one":
        merge(Path(sys.argv[2]), Path(sys.argv[3]))
        return
    work, results = Path(sys.argv[1]), Path(sys.argv[2])
    for folder in sorted(p for p in work.glob("*/*") if p.is_dir() and p.parent.name != "code"):
        building, forecast = folder.parent.name, folder.name
        if building.startswith("code-"):
            continue
        name = "year-planner" if forecast == "perfect" else f"year-planner-{forecast}"
        merge(folder, results / building / name)


if __name__ == "__main__":
    main()
