"""The algorithm comparison's figure and table, from a progress table and the committed reference rows."""

from __future__ import annotations

from pathlib import Path

import matplotlib.pyplot as plt
import pandas as pd

from parallel_eplus.evaluation.plots import REFERENCE_COLORS
from parallel_eplus.experiments.compare import compare_figure, compare_table, draw_comparison, references
from tests.test_plots import _inside

RESULTS = Path(__file__).parent.parent / "results" / "paper" / "results.csv"


def test_figure_and_table_show_each_algorithm_beside_the_reference_controllers(tmp_path):
    refs = references(RESULTS)
    assert set(refs) == {"Baseline", "Rule-based"} and refs["Rule-based"][1] < refs["Baseline"][1]
    progress = pd.DataFrame(
        [(a, s, s, s / 100, 50 + s / 1e4, 100 - s / 1e4, 0.1) for a in ("trpo", "sac") for s in (1000, 2000)],
        columns=["algorithm", "target", "steps", "wall_s", "in_band_pct", "power_kw", "reward_mean"],
    )
    assert compare_figure(progress, refs, tmp_path / "c.png").stat().st_size > 10_000
    table = compare_table(progress, refs)
    assert "| TRPO | 2,000 |" in table and "| SAC | 2,000 |" in table and "| Rule-based |" in table
    assert "| Baseline | - | - | 100.00 |" in table
    assert table.splitlines()[-1].endswith("| 0.10 |")  # the reward per step, the objective all three optimise


def test_figure_keeps_its_legend_outside_the_data_and_the_references_in_their_colours():
    refs = references(RESULTS)
    progress = pd.DataFrame(
        [(a, s, s, s / 100, 50 + s / 1e4, 100 - s / 1e4, 0.1) for a in ("trpo", "ppo", "sac") for s in (1000, 2000)],
        columns=["algorithm", "target", "steps", "wall_s", "in_band_pct", "power_kw", "reward_mean"],
    )
    fig = draw_comparison(progress, refs)
    try:
        assert _inside(fig) == []
        assert all(ax.get_legend() is None for ax in fig.axes)  # one legend, the figure's, beside the axes
        (legend,) = fig.legends
        shown = {t.get_text(): h.get_color() for t, h in zip(legend.get_texts(), legend.legend_handles, strict=True)}
        assert {k: shown[k] for k in REFERENCE_COLORS} == REFERENCE_COLORS
        assert len({shown[a] for a in ("TRPO", "PPO", "SAC")}) == 3
    finally:
        plt.close(fig)


def test_several_seeds_are_reported_as_their_mean_with_an_interval(tmp_path):
    refs = references(RESULTS)
    rows = [("trpo", seed, s, s, s / 100, 90 + seed, 100 - s / 1e4, 0.1) for seed in (0, 1, 2) for s in (1000, 2000)]
    progress = pd.DataFrame(
        rows, columns=["algorithm", "seed", "target", "steps", "wall_s", "in_band_pct", "power_kw", "reward_mean"]
    )
    table = compare_table(progress, refs)
    row = next(line for line in table.splitlines() if line.startswith("| TRPO (3 seeds) |"))
    assert "| 91.00 [90.00, 92.00] |" in row  # in band: seeds at 90, 91, 92
    assert compare_figure(progress, refs, tmp_path / "c.png").stat().st_size > 10_000
