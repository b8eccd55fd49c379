"""BOPTEST's figures on real short episodes of the small office (buildings/idf/thermostat.py, kpis.py, comfort.py).

The office's thermostats follow HTGSETP_SCH and CLGSETP_SCH (RefBldgSmallOfficeNew2004_Chicago.idf): 21.0 and
24.0 °C while the building is in use (weekdays 06-22 h), 15.6 and 26.7 °C set back otherwise.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from parallel_eplus.buildings.resources import model_file, spec_file
from parallel_eplus.buildings.spec.load import SpecError, load_spec
from parallel_eplus.evaluation.controllers import BASELINE_LABEL, Controller
from parallel_eplus.evaluation.sweep import run_sweep

OFFICE_IDF = model_file("RefBldgSmallOfficeNew2004_Chicago.idf")

EXTRA = """
[[observations]]
name = "building_power_w"               # lights and plug loads: what no HVAC controller touches
variable = "Facility Total Building Electricity Demand Rate"
key = "Whole Building"
low = 0.0
high = 1e9
"""


def office_spec(tmp_path: Path, kpis: str) -> Path:
    """The shipped office spec with another observation and its own `[kpis]`, beside the test's files."""
    text = spec_file("office-small").read_text()
    text = text.replace('idf = "RefBldgSmallOfficeNew2004_Chicago.idf"', f'idf = "{OFFICE_IDF}"')
    text = text.replace('baseline_idf = "RefBldgSmallOfficeNew2004_Chicago.idf"', f'baseline_idf = "{OFFICE_IDF}"')
    head, _, tail = text.partition("[[actions]]")
    text = head + EXTRA + "\n[[actions]]" + tail
    head, _, _ = text.partition("[kpis]")
    path = tmp_path / "office.toml"
    path.write_text(head + kpis)
    return path


TARIFF = """[kpis]
hvac = { Electricity = "hvac_power_w", NaturalGas = "NaturalGas:HVAC" }
tariff = { Electricity = { day = 0.30, night = 0.10, day_hours = [7, 22] }, NaturalGas = 0.05 }
emissions = { Electricity = 0.5, NaturalGas = 0.2 }
"""


@pytest.fixture(scope="module")
def baseline_episode(tmp_path_factory):
    """Two days (a Sunday, then a Monday: 2006 begins on a Sunday) of the office on its own controls."""
    tmp = tmp_path_factory.mktemp("kpis")
    spec = office_spec(tmp, TARIFF)
    df = run_sweep([Controller(BASELINE_LABEL, "baseline")], ["CA"], 2, 1, tmp / "out", False, building=str(spec))
    episode = Path(df["episode_dir"][0])
    return pd.read_parquet(episode / "steps.parquet"), json.loads((episode / "summary.json").read_text()), df


@pytest.mark.slow
def test_comfort_bounds_follow_the_setpoint_schedules(baseline_episode, no_leaks):
    steps, summary, df = baseline_episode
    low, high = steps["setpoint_htgsetp_sch"], steps["setpoint_clgsetp_sch"]
    start = steps["time"] - pd.Timedelta(minutes=10)
    hour = start.dt.hour
    in_use = (start.dt.day_of_week < 5) & (hour >= 6) & (hour < 22)
    assert in_use.any() and (~in_use).any()
    assert np.allclose(low[in_use], 21.0) and np.allclose(high[in_use], 24.0)
    assert np.allclose(low[~in_use], 15.6) and np.allclose(high[~in_use], 26.7)
    # the comfort figures count the occupied samples against those bounds: the built-in controls hold them
    assert summary["in_band_pct"] >= 95.0
    assert "band_low_c" not in df.columns  # no one band to name: each zone has its own
    # the bounds are not in the observation: the policy's input is unchanged
    from parallel_eplus.envs.env import observation_space

    assert observation_space(building="office-small").shape == (10,)


@pytest.mark.slow
def test_discomfort_counts_every_step_and_apart_the_occupied_ones(tmp_path, no_leaks):
    """BOPTEST's discomfort integrates each zone's slack at every step, against the setbacks while unoccupied; the
    occupied figure (an "occupied discomfort" goal's) counts the occupied steps alone. The office's own heating
    schedule 1 K lower (a correction of its own schedules): cold enough at night to leave the setback too."""
    action = np.array([0.0, -1.0 / 3.5], dtype=np.float32)  # heating -1 K: the action's half-range is 3.5 K
    colder = Controller(
        "colder", "policy", act=lambda obs, info: action, residual_scale=1.0, residual_space="builtin",
        building=str(spec_file("office-small")), time_features=True,
    )  # fmt: skip
    df = run_sweep([colder], ["CO"], 2, 1, tmp_path, False, building="office-small")
    episode = Path(df["episode_dir"][0])
    steps, summary = pd.read_parquet(episode / "steps.parquet"), json.loads((episode / "summary.json").read_text())
    low, high = steps["setpoint_htgsetp_sch"], steps["setpoint_clgsetp_sch"]
    zones = [c for c in steps if c.endswith("_temp_c") and c != "outdoor_temp_c"]
    slack = sum((low - steps[z]).clip(lower=0) + (steps[z] - high).clip(lower=0) for z in zones) / len(zones) / 6
    occupied = steps["comfort_applies"] > 0
    assert 0 < slack[occupied].sum() < slack.sum()
    assert summary["discomfort_kh"] == pytest.approx(slack.sum())
    assert summary["occupied_discomfort_kh"] == pytest.approx(slack[occupied].sum())


@pytest.mark.slow
def test_hvac_energy_excludes_lights_and_plugs(baseline_episode, no_leaks):
    steps, summary, _ = baseline_episode
    h = 10 / 60 / 1000  # kWh per W over a 10-minute step
    facility, building = steps["power_w"].sum() * h, steps["building_power_w"].sum() * h
    hvac = summary["hvac_electricity_kwh"]
    assert 0 < hvac < facility - building + 1e-6  # lights and plugs are in the facility's, never in the HVAC figure
    assert hvac == pytest.approx(facility - building, rel=0.02)  # what is left of the facility is the HVAC's
    gas = steps["gas_w"].sum() * h  # the furnaces and the water heater
    assert 0 < summary["hvac_naturalgas_kwh"] < gas  # the water heater's gas is not HVAC
    total = summary["hvac_electricity_kwh"] + summary["hvac_naturalgas_kwh"]
    assert summary["hvac_energy_kwh"] == pytest.approx(total)
    assert summary["floor_area_m2"] == pytest.approx(511.16, rel=1e-3)  # the model's five zones
    assert summary["hvac_energy_kwh_m2"] == pytest.approx(total / summary["floor_area_m2"])


@pytest.mark.slow
def test_cost_under_a_day_night_tariff_is_the_hand_computation(baseline_episode, no_leaks):
    steps, summary, _ = baseline_episode
    h = 10 / 60 / 1000
    cost = emissions = 0.0
    for _, r in steps.iterrows():
        start = r["time"] - pd.Timedelta(minutes=10)
        price = 0.30 if 7 <= start.hour < 22 else 0.10
        cost += r["hvac_power_w"] * h * price + r["hvac_naturalgas_w"] * h * 0.05
        emissions += r["hvac_power_w"] * h * 0.5 + r["hvac_naturalgas_w"] * h * 0.2
    assert summary["cost"] == pytest.approx(cost, rel=1e-9)
    assert summary["emissions_kg"] == pytest.approx(emissions, rel=1e-9)
    assert summary["cost_m2"] == pytest.approx(cost / summary["floor_area_m2"])


def test_spec_errors_name_the_bad_band_and_kpis(tmp_path):
    text = spec_file("office-small").read_text().replace("RefBldgSmallOfficeNew2004_Chicago.idf", str(OFFICE_IDF))
    bad = text.replace('band = "thermostat"', "band = { core_temp_c = [21.0, 24.0], kitchen = [20.0, 19.0] }")
    bad = bad.replace('tariff = { Electricity = { file = "commercial-tou-demand.toml" } }',
                      'tariff = { Electricity = "cheap" }\nemissions = { Coal = -1 }')  # fmt: skip
    path = tmp_path / "bad.toml"
    path.write_text(bad)
    with pytest.raises(SpecError) as e:
        load_spec(path)
    message = str(e.value)
    for expected in ("reward.band.kitchen", "no band for", "kpis.tariff.Electricity", "kpis.emissions.Coal"):
        assert expected in message
    per_zone = text.replace(
        'band = "thermostat"',
        "band = { core_temp_c = [21.0, 24.0], perimeter_1_temp_c = [20.0, 25.0], perimeter_2_temp_c = [20.0, 25.0],"
        " perimeter_3_temp_c = [20.0, 25.0], perimeter_4_temp_c = [19.0, 26.0] }",
    )
    path.write_text(per_zone)
    spec = load_spec(path)
    assert spec.reward.zone_bands[0] == (21.0, 24.0) and spec.reward.band == (19.0, 26.0)
    assert spec.reward.tolerance == 0.0 and load_spec(spec_file("office-small")).reward.tolerance == 0.2


@pytest.mark.slow
def test_a_scenario_period_lies_where_its_definition_says(tmp_path, no_leaks):
    """BOPTEST's days from the built-in controls' loads (here January's first 22 days: days 14-21 are available), and
    the run that scores one: a week of warm-up, then the two weeks centred on the day, on the same weekdays."""
    from parallel_eplus.evaluation.scenarios import LOADS, find_days, loads, period

    base = [Controller(BASELINE_LABEL, "baseline")]
    df = run_sweep(base, ["CA"], 22, 1, tmp_path / "loads", None, False, "office-small", extra_outputs=LOADS)
    year = Path(df["episode_dir"][0])
    heat, cool = loads(year)
    days = find_days(heat, cool)
    day_of = (heat.index.normalize() - heat.index[0].normalize()).days
    q = heat.resample("15min").mean()
    q_day = (q.index.normalize() - heat.index[0].normalize()).days
    assert q[q_day >= 14].idxmax().normalize() == heat.index[0].normalize() + pd.Timedelta(days=days["peak_heat"])
    daily = heat.groupby(day_of).max()  # the typical day: the highest daily peak at or below the median
    median = daily[daily > 1].median()
    assert daily[days["typical_heat"]] <= median
    assert (
        days["typical_heat"] >= 14
        and not (daily[(daily.index >= 14) & (daily <= median)] > daily[days["typical_heat"]]).any()
    )

    p = period("peak_heat", days["peak_heat"], heat.index[0].normalize().to_pydatetime())
    assert (p.start_day, p.run_days, p.warmup_days) == (days["peak_heat"] - 13, 21, 7)
    run = run_sweep(base, ["CA"], 1, 1, tmp_path / "period", None, False, "office-small", periods={"CA": p})
    summary = json.loads((Path(run["episode_dir"][0]) / "summary.json").read_text())
    first = heat.index[0].normalize() + pd.Timedelta(days=days["peak_heat"] - 7, minutes=10)
    assert pd.Timestamp(summary["period_start"]) == first  # the two weeks begin 7 days before the day
    assert pd.Timestamp(summary["period_end"]) == first + pd.Timedelta(days=14, minutes=-10)
    assert summary["steps"] == 14 * 144 and summary["warmup_days"] == 7
    steps = pd.read_parquet(Path(run["episode_dir"][0]) / "steps.parquet").set_index("time")
    before = pd.read_parquet(year / "steps.parquet").set_index("time")
    shared = steps.index.intersection(before.index)
    assert len(shared) > 7 * 144  # the same dates, on the same weekdays: the schedules fall as they did
    assert (steps.loc[shared, "setpoint_htgsetp_sch"] == before.loc[shared, "setpoint_htgsetp_sch"]).all()


@pytest.mark.slow
def test_the_loads_are_read_at_every_step_of_a_model_with_its_own_detailed_outputs(tmp_path, no_leaks):
    """The DOE medium office reports some of its own outputs at the HVAC's `Detailed` frequency, which adds rows to
    eplusout.csv between the steps: the loads the scenarios are found from are the steps' own, one per step."""
    from parallel_eplus.evaluation.scenarios import LOADS, loads

    base = [Controller(BASELINE_LABEL, "baseline")]
    df = run_sweep(base, ["CA"], 1, 1, tmp_path / "loads", None, False, "office-medium", extra_outputs=LOADS)
    heat, cool = loads(Path(df["episode_dir"][0]))
    assert len(heat) == len(cool) == 144 and not heat.isna().any() and not cool.isna().any()
    assert heat.index.is_monotonic_increasing and (heat > 0).any()  # January: the zones are heated


@pytest.mark.slow
def test_the_objective_sets_what_the_reward_pays_for(tmp_path, no_leaks):
    """`objective = "cost"`: the reward's energy term is each fuel's HVAC watts priced relative to electricity (here
    day 0.30, night 0.10: a mean of 0.2375), so the night's electricity costs less than the day's."""
    from parallel_eplus.engine.config import SimulationConfig
    from parallel_eplus.engine.simulation import Simulation

    spec = office_spec(tmp_path, TARIFF)
    sim = Simulation(SimulationConfig(weather="CA", building=str(spec), run_days=1, objective="cost"))
    weight = sim.config.reward.power_weight
    try:
        sim.start()
        for _ in range(30):
            sim.send(np.zeros(2))
            _, _, _, info = sim.receive()
            start = info["time"] - pd.Timedelta(minutes=10)
            price = 0.30 if 7 <= start.hour < 22 else 0.10
            mean = (15 * 0.30 + 9 * 0.10) / 24
            expected = (info["hvac_power_w"] * price + info["hvac_naturalgas_w"] * 0.05) / mean
            assert info["reward_power"] == pytest.approx(-weight * expected)
    finally:
        sim.close()
    with pytest.raises(ValueError, match="objective 'nonsense'"):
        Simulation(SimulationConfig(building=str(spec), objective="nonsense"))


def test_results_give_boptest_figures_beside_their_ratio_to_the_built_in(tmp_path):
    from parallel_eplus.evaluation.building_table import write_results

    rows = []
    for c, hvac, cost in ((BASELINE_LABEL, 4000.0, 400.0), ("Learned", 3000.0, 360.0)):
        rows.append({"controller": c, "weather": "CA", "power_kw": 5.0, "reward_mean": 0.0, "energy_kwh": 40000.0,
                     "peak_power_kw": 10.0, "discomfort_kh": 1.0, "core_in_band_pct": 99.0, "in_band_pct": 99.0,
                     "hvac_energy_kwh": hvac, "cost": cost, "emissions_kg": 1000.0, "floor_area_m2": 500.0,
                     "hvac_energy_kwh_m2": hvac / 500, "energy_kwh_m2": 80.0, "cost_m2": cost / 500,
                     "emissions_kg_m2": 2.0, "hvac_electricity_peak_kw_m2": 0.01})  # fmt: skip
    write_results(pd.DataFrame(rows), tmp_path, BASELINE_LABEL)
    text = (tmp_path / "results.md").read_text()
    assert "× built-in" in text and "per m² of the model's 500 m² floor" in text
    assert "| Learned | CA | 6.00 | 0.750 | 80.00 | 1.000 | 0.720 | 0.900 |" in text
    table = pd.read_csv(tmp_path / "results.csv").set_index("controller")
    assert table.loc["Learned", "hvac_energy_kwh_vs_builtin"] == pytest.approx(0.75)
    assert table.loc["Learned", "cost_vs_builtin"] == pytest.approx(0.9)


@pytest.mark.slow
def test_training_reports_each_episode_beside_the_built_in(tmp_path, no_leaks):
    """With `--init-from-baseline` the built-in controls' figures are at hand: every training episode's HVAC energy,
    cost, emissions and discomfort go to episodes.csv and TensorBoard also as ratios to them."""
    from parallel_eplus.training.config import TrainConfig
    from parallel_eplus.training.train import train

    cfg = TrainConfig(
        workers=1, weathers=["CA"], building="office-small", run_days=1, timesteps=144, batch_size=144,
        run_name="ratios", runs_dir=str(tmp_path / "runs"), tensorboard_dir=str(tmp_path / "tb"),
        init_from_baseline=True,
    )  # fmt: skip
    train(cfg, progress=False)
    run = tmp_path / "runs" / "ratios"
    builtin = pd.read_csv(run / "builtin.csv").iloc[0]
    episodes = pd.read_csv(run / "episodes.csv")
    assert len(episodes) >= 1
    for key in ("hvac_energy_kwh", "cost", "emissions_kg"):
        assert np.allclose(episodes[f"{key}_vs_builtin"], episodes[key] / builtin[key])
