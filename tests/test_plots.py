"""Figures (sweep, convergence, histogram) keep every artist inside the canvas and give each controller one colour."""

from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np
import pandas as pd
import pytest
from matplotlib.colors import to_hex

from parallel_eplus.engine.episode import STEPS_FILE
from parallel_eplus.evaluation import plots

REFERENCE = Path(__file__).resolve().parent.parent / "results" / "reference" / "results.csv"


def _inside(fig) -> list[str]:
    """Artists whose drawn extent leaves the canvas (matplotlib's tight bounding box, in inches)."""
    fig.canvas.draw()
    renderer = fig.canvas.get_renderer()
    tight, canvas = fig.get_tightbbox(renderer), fig.bbox_inches
    out = []
    if tight.x0 < -0.01 or tight.y0 < -0.01 or tight.x1 > canvas.x1 + 0.01 or tight.y1 > canvas.y1 + 0.01:
        out.append(f"figure content {tight} beyond canvas {canvas}")
    return out


@pytest.mark.parametrize("draw", [plots.temperature_comparison, plots.power_comparison])
def test_sweep_figures_not_clipped(draw, tmp_path, monkeypatch):
    df = pd.read_csv(REFERENCE)
    policy = df[df.controller == "Rule-based"].assign(controller="TRPO+RBC demand, 22.35 C, a long label (CA-CO-FL)")
    df = pd.concat([df, policy], ignore_index=True)
    figures = []
    monkeypatch.setattr(plots, "_save", lambda fig, path: figures.append(fig) or path)
    draw(df, tmp_path / "figure.png")
    assert _inside(figures[0]) == []
    plt.close(figures[0])


def test_references_added_and_colours_fixed():
    refs = pd.read_csv(REFERENCE)
    lone = refs[refs.controller == "Rule-based"].assign(controller="TRPO (CA)")
    shown = plots.with_references(lone, refs)
    assert list(dict.fromkeys(shown.controller)) == ["Baseline", "Rule-based", "TRPO (CA)"]
    assert plots.controller_color("Baseline") != plots.controller_color("Rule-based")
    assert plots.controller_color("TRPO (CA)") == plots.controller_color("TRPO (CA)")


def test_policies_hashed_alike_get_distinct_colours_in_one_figure():
    # Both labels hash to the same palette entry; in one figure the second must move, the first keep its own.
    first, second = "TRPO (CA-CO-FL) 1M, online", "TRPO (CA-CO-FL) 10.5M, online"
    assert plots.controller_color(first) == plots.controller_color(second)
    colors = plots.controller_colors(["Baseline", "Rule-based", first, second])
    assert len(set(colors.values())) == 4
    assert colors[first] == plots.controller_color(first) and colors["Rule-based"] == "tab:green"


def test_convergence_shows_the_references_only_on_the_reward_they_were_scored_with(tmp_path, monkeypatch):
    models = REFERENCE.parents[1] / "paper" / "models"
    refs = pd.read_csv(REFERENCE)
    ca = refs[refs.weather == "CA"]
    expected = {c: ca[ca.controller == c].reward_mean.item() for c in plots.REFERENCE_COLORS}
    assert plots.reference_rewards(models / "paper-ca", ["CA"]) == pytest.approx(expected)
    assert plots.reference_rewards(models / "residual-demand", ["CA", "CO", "FL"]) == {}  # trained on another reward
    figures = []
    monkeypatch.setattr(plots, "_save", lambda fig, path: figures.append(fig) or path)
    plots.convergence(models / "paper-ca-co-fl", tmp_path / "convergence.png")
    assert _inside(figures[0]) == [] and figures[0].axes[0].get_legend() is None  # the legend beside the axes
    assert {"Baseline, mean of CA/CO/FL", "Rule-based, mean of CA/CO/FL"} <= {
        t.get_text() for t in figures[0].legends[0].get_texts()
    }
    plt.close(figures[0])


def test_histogram_title_fits_and_the_bars_wear_the_controllers_colour(tmp_path, monkeypatch):
    label = "TRPO+RBC demand, 22.35 C, band x5 (CA-CO-FL)"  # ran off the edge before titles wrapped
    pd.DataFrame({"west_temp_c": np.random.default_rng(0).normal(22.4, 0.15, 500)}).to_parquet(tmp_path / STEPS_FILE)
    figures = []
    monkeypatch.setattr(plots, "_save", lambda fig, path: figures.append(fig) or path)
    plots.west_zone_histogram(tmp_path, (label, "VA"), tmp_path / "histogram.png")
    assert _inside(figures[0]) == []
    assert to_hex(figures[0].axes[0].patches[0].get_facecolor()) == to_hex(plots.controller_color(label))
    plt.close(figures[0])
