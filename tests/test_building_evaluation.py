"""Evaluation counts, reports and controls in the building's own terms: its control step, zones and band.

The CRAC data center steps every 10 minutes (144 steps a day, the 2-zone model 96): code that counted the
data center's steps cuts its episodes short or miscounts them.
"""

from __future__ import annotations

import json
from pathlib import Path

import pandas as pd
import pytest

from parallel_eplus.evaluation.controllers import BASELINE_LABEL, RBC_LABEL, Controller, policy_controller
from parallel_eplus.evaluation.redraw import plot_path
from parallel_eplus.evaluation.sweep import run_sweep

CRAC = "datacenter-crac"


def test_sweep_and_online_evaluation_count_and_run_the_buildings_whole_episode(tmp_path, capsys, no_leaks):
    """A sweep counts the building's steps (144 a day here, not 96) for its own controls and a policy trained on it,
    and `evaluate --online` learns for one whole episode of it."""
    from parallel_eplus.experiments.online import run_online
    from parallel_eplus.training.config import TrainConfig
    from parallel_eplus.training.train import train

    cfg = TrainConfig(
        workers=1, weathers=["CA"], building=CRAC, run_days=1, timesteps=32, batch_size=32, run_name="crac",
        runs_dir=str(tmp_path / "runs"), tensorboard_dir=str(tmp_path / "tb"),
    )  # fmt: skip
    final = train(cfg, progress=False)
    # A built-in spec is saved by name; saved by path by another checkout or install (older runs), it is
    # found by its name where this one keeps it.
    config = final.parent / "config.json"
    saved = json.loads(config.read_text())
    assert saved["building"] == "datacenter-crac"
    elsewhere = "/elsewhere/parallel_eplus/buildings/specs/datacenter-crac.toml"
    config.write_text(json.dumps({**saved, "building": elsewhere}))
    policy = policy_controller(str(final))
    assert policy.building
    base = Controller(BASELINE_LABEL, "baseline")
    df = run_sweep([base, policy], ["CA"], 1, 1, tmp_path / "frozen", progress=True, building=CRAC)
    assert df["steps"].tolist() == [144, 144] and (df["band_low_c"][0], df["band_high_c"][0]) == (18.0, 27.0)
    assert "288/288" in capsys.readouterr().err  # the progress bar's total: two episodes of the building's day
    figure = plot_path(Path(df["episode_dir"][0]))  # its time series: the servers' inlet air and its band
    assert figure.is_file() and figure.stat().st_size > 1000
    df = run_online([policy], ["CA"], 1, 1, tmp_path / "eval", batch_size=16)
    assert df["steps"].tolist() == [144] and df["online_updates"].tolist() == [144 // 16]


def test_rule_based_controller_comes_from_the_spec(tmp_path):
    """`--rbc` runs the controller a spec names, and refuses a building it cannot drive, before any run."""
    with pytest.raises(ValueError, match="controller"):  # the CRAC's spec names none
        run_sweep([Controller(RBC_LABEL, "rbc")], ["CA"], 1, 1, tmp_path, progress=False, building=CRAC)
    with pytest.raises(ValueError, match="4 actions"):  # the data center's, but only two of its actions
        Controller(RBC_LABEL, "rbc").make("datacenter-2zone-temp")
    assert len(Controller(RBC_LABEL, "rbc").make("datacenter-2zone").temperatures) == 2
    reset = Controller(RBC_LABEL, "rbc", rule="parallel_eplus.buildings.rules.air_reset:SupplyAirReset")
    with pytest.raises(ValueError, match="no supply-air action"):  # a rule named (--rbc CLASS) acts, on any building
        reset.make(None)
    assert not list(tmp_path.iterdir())  # nothing ran


def test_building_results_name_the_band(tmp_path):
    from parallel_eplus.evaluation.building_table import write_results

    df = pd.DataFrame(
        [
            {"controller": c, "weather": "CA", "power_kw": p, "reward_mean": -1.0, "it_inlet_in_band_pct": b,
             "it_inlet_temp_mean": 20.0, "it_inlet_temp_std": 1.0, "it_inlet_temp_min": 18.0,
             "it_inlet_temp_max": 24.0, "in_band_pct": b, "band_low_c": 18.0, "band_high_c": 27.0}
            for c, p, b in ((BASELINE_LABEL, 100.0, 100.0), ("TRPO (CA)", 90.0, 99.0))
        ]
    )  # fmt: skip
    files = write_results(df, tmp_path, BASELINE_LABEL)
    text = (tmp_path / "results.md").read_text()
    assert "18–27 °C" in text and "-10.0 %" in text
    assert {f.name for f in files} >= {"results.csv", "results.md", "temperatures.png", "power.png"}


def test_averages_leave_out_a_weather_a_controller_did_not_finish():
    """The CRAC's own controls fail on CO: its average and the policy's are both over the other weathers."""
    from parallel_eplus.evaluation.building_table import table_markdown

    rows = [(BASELINE_LABEL, "CA", 100.0), (BASELINE_LABEL, "FL", 120.0),
            ("TRPO", "CA", 90.0), ("TRPO", "CO", 10.0), ("TRPO", "FL", 108.0)]  # fmt: skip
    df = pd.DataFrame(
        [{"controller": c, "weather": w, "power_kw": p, "zone_in_band_pct": 100.0, "in_band_pct": 100.0}
         for c, w, p in rows]
    )  # fmt: skip
    text = table_markdown(df, BASELINE_LABEL)
    assert "Averages over CA, FL, the weathers every controller finished (not CO)." in text
    assert "| TRPO | 99.00 | -10.0 % | 100.00 % |" in text  # (90 + 108) / 2 against (100 + 120) / 2
    from parallel_eplus.evaluation.plots import weather_order

    assert weather_order(df["weather"]) == ["CA", "CO", "FL"]  # in the figures too, CO keeps its place


def test_a_specs_time_features_apply(tmp_path):
    """office-small declares `time_features = true`: its env and its training runs observe the clock."""
    from parallel_eplus.envs.env import EnergyPlusEnv
    from parallel_eplus.training.config import TrainConfig

    env = EnergyPlusEnv(building="office-small", output_dir=tmp_path)
    try:
        assert env.observation_space.shape == (10 + 4,) and env.config.time_features  # 8 sensors, gas, occupancy
    finally:
        env.close()
    assert EnergyPlusEnv(building="office-small", time_features=False, output_dir=tmp_path).observation_space.shape == (
        10,
    )
    assert TrainConfig(building="office-small").resolved().time_features
    assert not TrainConfig(building=CRAC).resolved().time_features


def test_a_building_policys_features_are_read_beside_its_sensors(tmp_path, no_leaks):
    """office-small observes 8 sensors and the clock: its policy's 12 observations are that, not the data center's."""
    from parallel_eplus.training.config import TrainConfig
    from parallel_eplus.training.train import train

    cfg = TrainConfig(
        workers=1, weathers=["CA"], building="office-small", run_days=1, timesteps=32, batch_size=32, run_name="o",
        runs_dir=str(tmp_path / "runs"), tensorboard_dir=str(tmp_path / "tb"),
    )  # fmt: skip
    policy = policy_controller(str(train(cfg, progress=False)))
    assert (policy.time_features, policy.schedule_features) == (True, False)


def test_the_medium_offices_rule_resets_its_supply_air_and_leaves_its_thermostats_to_their_schedules(
    tmp_path, no_leaks
):
    """`--rbc` on the medium office: Guideline 36's supply-air reset (buildings/rules/air_reset.py) on the three loops'
    node, every thermostat released to the building's own schedules. In San Francisco's January (outdoor air below
    16 C) the reset sits at its 18 C top; the zones stay on their own setpoints, so the episode is the building's
    own controls but for warmer supply air: the reheat it saves shows in the HVAC energy (a sunny zone's requests
    trim it for an hour or two)."""
    base, rule = Controller(BASELINE_LABEL, "baseline"), Controller(RBC_LABEL, "rbc")
    df = run_sweep([base, rule], ["CA"], 2, 2, tmp_path, progress=False, building="office-medium")
    steps = pd.read_parquet(Path(df.set_index("controller").loc[RBC_LABEL, "episode_dir"]) / "steps.parquet")
    cold = steps["outdoor_temp_c"] < 16
    at_top = steps.loc[cold, "supply_air_c"] == 18.0
    assert cold.mean() > 0.9 and at_top.mean() > 0.8  # trimmed down only while a zone asks for cooling
    assert steps["supply_air_c"].between(12.8, 18.0).all()
    assert steps[["cooling_setpoint_c", "heating_setpoint_c"]].isna().all().all()  # released: the schedules set them
    hvac = df.set_index("controller")["hvac_energy_kwh"]
    assert hvac[RBC_LABEL] < 0.97 * hvac[BASELINE_LABEL]
    assert Controller(RBC_LABEL, "rbc").relinquishes("office-medium")
    assert not Controller(RBC_LABEL, "rbc").relinquishes("datacenter-2zone")


def test_pre_cooling_follows_the_tariffs_peak_window_and_releases_the_rest(tmp_path, no_leaks):
    """`--rbc parallel_eplus.buildings.rules.precool:PreCool` on the small office under its example tariff, a July
    Wednesday: the cooling setpoints 2 K below their own schedule's 24 C from 4 h before the summer peak window
    (weekdays 12-18 h) and back to it by the window's end, clipped at the spec's 23 C floor; released (NaN: the own
    schedules) at every other hour and for the heating setpoints. The zones enter the window cooler than under
    their own controls."""
    from parallel_eplus.buildings.building import load_building
    from parallel_eplus.evaluation.scenarios import Period

    rule = "parallel_eplus.buildings.rules.precool:PreCool"
    with pytest.raises(ValueError, match="cannot be imported"):
        load_building("office-small").controller_class("parallel_eplus.buildings.rules.precool:Nothing")
    base, pre = Controller(BASELINE_LABEL, "baseline"), Controller("pre-cool", "rbc", rule=rule)
    assert pre.relinquishes("office-small")
    july = Period("summer weekday", day=185, start_day=186, weekday="Wednesday", run_days=1, warmup_days=0)
    df = run_sweep([base, pre], ["CA"], 2, 2, tmp_path, progress=False, building="office-small", periods={"CA": july})
    dirs = df.set_index("controller")["episode_dir"]
    steps = {c: pd.read_parquet(Path(d) / "steps.parquet").set_index("time") for c, d in dirs.items()}
    s = steps["pre-cool"]
    assert (s.index[0].month, s.index[0].day, s.index[0].day_name()) == (7, 5, "Wednesday")
    begins = s.index - pd.Timedelta(minutes=10)  # a step's action applies from its start
    hour = begins.hour + begins.minute / 60
    lead, window = (hour >= 8) & (hour < 12), (hour >= 12) & (hour < 18)
    own = s["setpoint_clgsetp_sch"].shift(1)  # the schedule as read when the action was chosen
    expected = (own - 2 * ((18 - hour) / 6).where(window, 1.0)).clip(lower=23.0)
    assert (s.loc[lead, "cooling_setpoint_c"] == 23.0).all()
    assert ((s.loc[window, "cooling_setpoint_c"] - expected[window]).abs() < 1e-3).all()
    assert s.loc[~(lead | window), "cooling_setpoint_c"].isna().all() and s["heating_setpoint_c"].isna().all()
    noon = s.index == s.index[0].normalize() + pd.Timedelta(hours=12)
    zones = [c for c in s.columns if c.endswith("_temp_c") and c != "outdoor_temp_c"]
    cooler = steps[BASELINE_LABEL].loc[noon, zones].to_numpy() - s.loc[noon, zones].to_numpy()
    assert (cooler > 0.3).all(), cooler


def _medium_office_with(tmp_path: Path, lines: str, name: str) -> Path:
    """The shipped medium office's spec with `lines` after its `controller`, as NAME.toml."""
    from parallel_eplus.buildings.resources import spec_file

    text = spec_file("office-medium").read_text()
    spec = tmp_path / f"{name}.toml"
    spec.write_text(text.replace('controller = "', f'{lines}\ncontroller = "', 1))
    return spec


def test_the_specs_controller_settings_reach_its_rule(tmp_path, no_leaks):
    """`controller_settings = { max_c = 16.0 }`: the reset's top at 16 C, not Guideline 36's 18 C, in a real day of
    San Francisco's January (outdoor air below 16 C: the reset at its top); a setting the rule does not have fails
    before anything runs, with the names it takes."""
    spec = _medium_office_with(tmp_path, "controller_settings = { max_c = 16.0 }", "top")
    df = run_sweep([Controller(RBC_LABEL, "rbc")], ["CA"], 1, 1, tmp_path / "out", progress=False, building=str(spec))
    steps = pd.read_parquet(Path(df.loc[0, "episode_dir"]) / "steps.parquet")
    top = steps["supply_air_c"].round(4)  # float32 through the normalized action
    assert top.max() == 16.0 and (top == 16.0).mean() > 0.8
    typo = _medium_office_with(tmp_path, "controller_settings = { request_kk = 0.02 }", "typo")
    with pytest.raises(ValueError, match='no setting .request_kk.; close: "request_k"'):
        Controller(RBC_LABEL, "rbc").make(str(typo))
