"""Results across seeds: means, bootstrap intervals and the IQM on known numbers; tables and figures from them."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from parallel_eplus.evaluation import seeds
from parallel_eplus.evaluation.building_table import write_results


def runs_table() -> pd.DataFrame:
    """A baseline and one recipe's three runs on two weathers (a building's results rows)."""
    zone = dict(core_temp_mean=22.0, core_temp_std=1.0, core_temp_min=20.0, core_temp_max=25.0)
    rows = [dict(controller="Baseline", run="", weather=w, energy_kwh=1000.0, power_kw=10.0, peak_power_kw=12.0,
                 in_band_pct=90.0, discomfort_kh=5.0, core_in_band_pct=90.0, **zone) for w in ("CA", "FL")]  # fmt: skip
    for k, (energy, band) in enumerate([(800.0, 95.0), (850.0, 97.0), (900.0, 99.0)]):
        for w, shift in (("CA", 0.0), ("FL", 50.0)):
            rows.append(dict(controller="TRPO", run=f"seed-{k}", weather=w, energy_kwh=energy + shift,
                             power_kw=(energy + shift) / 100, peak_power_kw=11.0, in_band_pct=band,
                             discomfort_kh=1.0 + k, core_in_band_pct=band, **zone))  # fmt: skip
    return pd.DataFrame(rows)


def test_means_intervals_and_iqm_over_seeds():
    table = seeds.seed_table(runs_table(), "Baseline").set_index(["weather", "metric"])
    assert set(table.index.get_level_values("weather")) == {"CA", "FL", "all"}  # the baseline has one run: none
    ca = table.loc[("CA", "energy_change_pct")]
    assert ca["mean"] == pytest.approx(-15.0) and ca["runs"] == 3  # -20, -15, -10
    assert -20.0 - 1e-9 <= ca["low"] <= -18.0 and -12.0 <= ca["high"] <= -10.0 + 1e-9
    overall = table.loc[("all", "energy_change_pct")]
    assert overall["mean"] == pytest.approx(np.mean([-20, -15, -10, -15, -10, -5]))
    assert overall["iqm"] == pytest.approx(float(seeds.iqm(np.array([-20, -15, -10, -15, -10, -5]))))
    assert overall["low"] < overall["mean"] < overall["high"]
    band = table.loc[("all", "in_band_pct")]
    assert band["mean"] == pytest.approx(97.0) and 95.0 <= band["low"] <= band["high"] <= 99.0
    one = seeds.interval([np.array([3.0])])
    assert one[0] == 3.0 and np.isnan(one[1])  # one run: no interval


def test_noisy_years_are_compared_with_the_baselines_same_year():
    # two noisy years of one weather: the baseline uses 1000 then 1200 kWh; a controller 10 % less each year
    rows = [
        dict(controller=c, run=f"year {k}", weather="CA", weather_seed=k, energy_kwh=e, cost=e / 10)
        for c, scale in (("Baseline", 1.0), ("TRPO", 0.9))
        for k, e in ((0, 1000.0 * scale), (1, 1200.0 * scale))
    ]
    df = seeds.with_changes(pd.DataFrame(rows), "Baseline")
    trpo = df[df.controller == "TRPO"]
    assert trpo["energy_change_pct"].to_numpy() == pytest.approx([-10.0, -10.0])  # unpaired: -18.2 and -1.8
    assert trpo["cost_change_pct"].to_numpy() == pytest.approx([-10.0, -10.0])
    missing = seeds.with_changes(pd.DataFrame(rows + [{**rows[-1], "weather_seed": 7}]), "Baseline")
    assert missing["energy_change_pct"].iloc[-1] == pytest.approx(100 * (1080 / 1100 - 1))  # the weather's mean


def test_runs_are_averaged_in_the_tables_and_reported_across_seeds(tmp_path):
    df = runs_table()
    collapsed = seeds.collapse(df)
    assert len(collapsed) == 4 and collapsed.set_index(["controller", "weather"]).loc[("TRPO", "CA"), "runs"] == 3
    files = write_results(collapsed, tmp_path, "Baseline", df, seeds.seed_table(df, "Baseline"))
    md = (tmp_path / "results.md").read_text()
    assert "## Across runs (seeds)" in md and "**TRPO** (3 runs)" in md and "energy vs built-in (%)" in md
    assert "| TRPO | CA | 8.50 | 850 | -15.0 % |" in md  # the runs' mean in the per-weather table
    assert len(pd.read_csv(tmp_path / "results.csv")) == 8 and (tmp_path / "seeds.csv") in files
    assert (tmp_path / "power.png").stat().st_size > 0
