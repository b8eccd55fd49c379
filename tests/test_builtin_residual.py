"""Thermostat actions land at the step they are meant for, and a policy can correct the building's own schedules.

The small office's thermostats follow HTGSETP_SCH and CLGSETP_SCH: 21.0 and 24.0 °C weekdays 06-22 h, 15.6 and
26.7 °C set back otherwise. 2006 begins on a Sunday, so the second day has the 06:00 change the tests look at.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from parallel_eplus.envs.env import EnergyPlusEnv
from parallel_eplus.evaluation.controllers import BASELINE_LABEL, Controller
from parallel_eplus.evaluation.sweep import run_sweep

DAYS = 2


def _episode(out: Path, act, scale: float = 0.3, building: str = "office-small") -> pd.DataFrame:
    env = EnergyPlusEnv(building=building, weather="CA", run_days=DAYS, output_dir=out, residual_scale=scale,
                        residual_space="builtin")  # fmt: skip
    try:
        obs, info = env.reset(seed=0)
        terminated = False
        while not terminated:
            obs, _, terminated, _, info = env.step(act(obs, info))
        return pd.read_parquet(Path(info["episode_dir"]) / "steps.parquet")
    finally:
        env.close()


@pytest.mark.slow
def test_a_zero_correction_is_the_buildings_own_controls_step_for_step(tmp_path, no_leaks):
    df = run_sweep([Controller(BASELINE_LABEL, "baseline")], ["CA"], DAYS, 1, tmp_path / "own", False,
                   building="office-small")  # fmt: skip
    own = pd.read_parquet(Path(df["episode_dir"][0]) / "steps.parquet")
    zero = _episode(tmp_path / "zero", lambda obs, info: np.zeros(2, np.float32))
    # The thermostats are set before the zone predictor reads them: set after it (as node setpoints are), the
    # 06:00 change would act at 06:10, and the Monday morning's heating would differ by ~16 kW for a step.
    for column in ("core_temp_c", "perimeter_1_temp_c", "power_w", "gas_w"):
        np.testing.assert_array_equal(zero[column].to_numpy(), own[column].to_numpy(), err_msg=column)
    assert (zero.heating_setpoint_c == zero.setpoint_htgsetp_sch).all()
    assert {21.0, 15.6} <= set(zero.heating_setpoint_c.round(2))  # the schedule changed within the episode


@pytest.mark.slow
def test_a_correction_moves_each_setpoint_from_its_schedule_within_bounds(tmp_path, no_leaks):
    # +1 cooling: 0.3 of half of 23-30 °C above CLGSETP_SCH; -1 heating: 0.3 of half of 15-22 °C below HTGSETP_SCH,
    # but never below the action's 15 °C (15.6 - 1.05 is clipped there)
    df = _episode(tmp_path / "moved", lambda obs, info: np.array([1.0, -1.0], np.float32))
    np.testing.assert_allclose(df.cooling_setpoint_c - df.setpoint_clgsetp_sch, 1.05)
    expected = np.maximum(df.setpoint_htgsetp_sch - 1.05, 15.0)
    np.testing.assert_allclose(df.heating_setpoint_c, expected)
    assert (df.heating_setpoint_c == 15.0).any() and (df.heating_setpoint_c > 19.0).any()


@pytest.mark.slow
def test_a_supply_air_its_scheduled_manager_set_is_corrected_from_that_schedule(tmp_path, no_leaks):
    """The medium office's three loops' supply air follows a `SetpointManager:Scheduled` (12.8 C): the copy drops the
    manager and the correction is added to its schedule, so a zero correction is the building's own controls."""
    df = run_sweep([Controller(BASELINE_LABEL, "baseline")], ["CA"], DAYS, 1, tmp_path / "own", False,
                   building="office-medium")  # fmt: skip
    own = pd.read_parquet(Path(df["episode_dir"][0]) / "steps.parquet")
    zero = _episode(tmp_path / "zero", lambda obs, info: np.zeros(3, np.float32), building="office-medium")
    for column in ("core_mid_temp_c", "perimeter_bot_zn_1_temp_c", "hvac_power_w", "gas_w"):
        np.testing.assert_allclose(zero[column], own[column], rtol=1e-6, atol=1e-6, err_msg=column)
    assert (zero.supply_air_c == zero.setpoint_seasonal_reset_supply_air_temp_sch).all()
    warmer = _episode(tmp_path / "warmer", lambda obs, info: np.array([0, 0, 1], np.float32), building="office-medium")
    np.testing.assert_allclose(warmer.supply_air_c, 12.8 + 0.3 * 3.0)  # 0.3 of half of 12-18 C above the schedule


def test_only_a_buildings_thermostats_can_be_corrected():
    with pytest.raises(ValueError, match=r"supply_temp_c .*no setpoint schedule of the building's own"):
        EnergyPlusEnv(building="datacenter-crac", residual_scale=0.2, residual_space="builtin")
    with pytest.raises(ValueError, match="pass --building"):
        EnergyPlusEnv(residual_scale=0.2, residual_space="builtin")


@pytest.mark.slow
def test_a_heating_setpoint_above_its_zones_cooling_setpoint_is_lowered_to_it(tmp_path, no_leaks):
    # Overlapping bounds (as a starter's operating rooms have) let an action cross a dual-setpoint thermostat, which
    # stops EnergyPlus ("Effective heating set-point higher than effective cooling set-point"); lowered to the cooling
    # setpoint, the episode runs and its record shows what EnergyPlus got.
    from parallel_eplus.buildings.resources import spec_file

    text = spec_file("office-small").read_text()
    spec = tmp_path / "office-overlap.toml"
    spec.write_text(text.replace("low = 15.0\nhigh = 22.0", "low = 15.0\nhigh = 26.0", 1))
    env = EnergyPlusEnv(building=str(spec), weather="CA", run_days=1, output_dir=tmp_path / "out")
    try:
        env.reset(seed=0)
        crossed = np.array([-1.0, 1.0], np.float32)  # cooling 23 C, heating 26 C (the spec's order)
        terminated = False
        while not terminated:
            _, _, terminated, _, info = env.step(crossed)
        df = pd.read_parquet(Path(info["episode_dir"]) / "steps.parquet")
    finally:
        env.close()
    assert len(df) == 144 and (df.cooling_setpoint_c == 23.0).all()  # a day of 10-minute steps
    assert (df.heating_setpoint_c == 23.0).all()


@pytest.mark.slow
def test_a_rule_that_corrects_the_own_schedules_holds_each_thermostat_its_margin_inside(tmp_path, no_leaks):
    """`OwnMargin` (a rule whose actions correct the building's own schedules) keeps each setpoint 0.5 K inside its
    schedule at every step, the 06:00 change included: from the observation, a rule sees the schedule of the step
    that ended and would hold the setback's 26.7 C for that step."""
    from parallel_eplus.buildings.resources import spec_file
    from parallel_eplus.evaluation.controllers import RBC_LABEL

    text = spec_file("office-small").read_text()
    rule = (
        'controller = "parallel_eplus.buildings.rules.own_margin:OwnMargin"\ncontroller_settings = { margin_k = 0.5 }\n'
    )
    spec = tmp_path / "margin.toml"
    spec.write_text(text.replace("[weathers]", rule + "[weathers]", 1))
    df = run_sweep([Controller(RBC_LABEL, "rbc")], ["CA"], DAYS, 1, tmp_path / "out", False, building=str(spec))
    steps = pd.read_parquet(Path(df["episode_dir"][0]) / "steps.parquet")
    np.testing.assert_allclose(steps.cooling_setpoint_c, steps.setpoint_clgsetp_sch - 0.5, atol=1e-4)
    np.testing.assert_allclose(steps.heating_setpoint_c, steps.setpoint_htgsetp_sch + 0.5, atol=1e-4)
    assert {23.5, 26.2} <= set(steps.cooling_setpoint_c.round(2))  # the schedule changed within the episode
    wide = tmp_path / "wide.toml"
    wide.write_text(text.replace("[weathers]", rule.replace("0.5", "3.0") + "[weathers]", 1))
    with pytest.raises(ValueError, match="margin_k 3.0 K: within"):
        Controller(RBC_LABEL, "rbc").make(str(wide))
