"""`parallel-eplus plot PATH`: whatever folder it is given, its figures drawn again from what it saved.

A run draws its convergence, an episode its time series, an evaluation sweep its comparison figures (the paper's,
or another building's own through building_table.py).
"""

from __future__ import annotations

from pathlib import Path

import pandas as pd

from parallel_eplus.engine.episode import STEPS_FILE, SUMMARY_FILE
from parallel_eplus.evaluation import building_table, plots


def sweep(out_dir: Path) -> list[Path]:
    """Redraws a saved sweep's temperatures.png and power.png from its results.csv, with the references.

    The built-in and rule-based controllers come from `reference/results.csv` above `out_dir` when
    the sweep did not run them itself; another building's sweep draws only its own rows, against its band.
    """
    df = pd.read_csv(out_dir / "results.csv")
    if building_table.is_generic(df):
        return building_table.figures(df, out_dir)
    df = plots.with_references(df, plots.find_references(out_dir))
    return [
        plots.temperature_comparison(df, out_dir / "temperatures.png"),
        plots.power_comparison(df, out_dir / "power.png"),
    ]


def plot_path(path: Path) -> Path | list[Path]:
    """A run directory draws its convergence; an episode directory its time series; a sweep its figures."""
    if (path / "episodes.csv").is_file():
        return plots.convergence(path)
    if (path / "results.csv").is_file():
        return sweep(path)
    if (path / STEPS_FILE).is_file():
        return plots.episode(path)
    if (path / SUMMARY_FILE).is_file():
        raise FileNotFoundError(f"{path} kept only its summary (older episodes are pruned); pick a newer one")
    raise FileNotFoundError(f"{path} is neither a run directory (episodes.csv) nor an episode directory ({STEPS_FILE})")
