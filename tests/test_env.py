"""EnergyPlusEnv against real EnergyPlus processes on short run periods."""

from __future__ import annotations

import tempfile
from pathlib import Path

import gymnasium as gym
import numpy as np
import pandas as pd
import pytest
from gymnasium.utils.env_checker import check_env

import parallel_eplus
from parallel_eplus import EnergyPlusEnv
from parallel_eplus.buildings.datacenter import SENSOR_NAMES, STEPS_PER_DAY
from parallel_eplus.engine.config import SimulationConfig
from parallel_eplus.engine.episode import read_steps
from parallel_eplus.engine.simulation import Simulation

INFO_KEYS = {"power_w", "it_power_w", "hvac_power_w", "west_temp_c", "east_temp_c", "outdoor_temp_c", "time"}


def run_episode(env, action) -> tuple[int, list[float], dict]:
    env.reset(seed=0)
    rewards, terminated, info = [], False, {}
    while not terminated:
        _, r, terminated, truncated, info = env.step(action)
        assert not truncated
        rewards.append(r)
    return len(rewards), rewards, info


@pytest.mark.slow
def test_registered_and_two_day_episode_steps_exactly(tmp_path, no_leaks):
    env = gym.make(parallel_eplus.ENV_ID, weather="CA", model="temp_fan", run_days=2, output_dir=tmp_path)
    try:
        obs, info = env.reset(seed=0)
        assert obs.shape == (6,) and obs.dtype == np.float32
        assert env.observation_space.contains(obs)
        assert str(info["time"]) == "2013-01-01 00:00:00"
        n, rewards, info = run_episode(env, np.zeros(4, dtype=np.float32))
        assert n == 2 * STEPS_PER_DAY
        assert np.all(np.isfinite(rewards))
        assert INFO_KEYS | {"reward_comfort", "reward_band", "reward_power"} <= set(info)
        assert info["reward_comfort"] + info["reward_band"] + info["reward_power"] == pytest.approx(rewards[-1])
        # The last observation is a real one, taken at the end of the run period.
        assert (info["time"].month, info["time"].day, info["time"].hour) == (1, 3, 0)
        assert info["power_w"] > info["it_power_w"] > 0
    finally:
        env.close()


def test_episode_records(tmp_path, no_leaks):
    env = EnergyPlusEnv(weather="FL", run_days=1, output_dir=tmp_path)
    try:
        n, rewards, info = run_episode(env, np.array([-0.6, -0.6, 0.2, 0.2]))
    finally:
        env.close()
    ep = tmp_path / "episode-000001-FL"
    assert {"model.idf", "steps.parquet", "summary.json", "eplusout.err", "eplusout.csv"} <= {
        p.name for p in ep.iterdir()
    }
    assert any(p.suffix == ".epw" for p in ep.iterdir())
    steps = read_steps(ep)
    assert len(steps) == n == STEPS_PER_DAY
    assert set(SENSOR_NAMES) <= set(steps.columns)
    np.testing.assert_allclose(steps["west_setpoint_c"], 16.0)  # -0.6 -> 10 + 0.2 * 30
    np.testing.assert_allclose(steps["east_fan_kg_s"], 1.75 + 0.6 * 5.25)
    np.testing.assert_allclose(steps["reward"], rewards, rtol=1e-8, atol=1e-9)
    assert pd.api.types.is_datetime64_any_dtype(steps["time"])
    summary = info["episode_summary"]
    assert summary["power_kw"] == pytest.approx(steps["power_w"].mean() / 1000)
    assert 0 <= summary["in_band_pct"] <= 100
    # EnergyPlus's own timestep output agrees with what the env observed.
    eplus = pd.read_csv(ep / "eplusout.csv")
    col = next(c for c in eplus.columns if c.startswith("WEST ZONE:Zone Mean Air Temperature"))
    np.testing.assert_allclose(eplus[col].to_numpy()[-n:], steps["west_temp_c"], atol=1e-3)


def test_without_energyplus_csv_the_simulation_is_the_same(tmp_path, no_leaks):
    """Training turns EnergyPlus's own CSV off (it holds every value in memory all year): only the file goes,
    every observation and reward stays the same to the bit, and only that one field of the model changes."""
    actions = np.clip(np.random.default_rng(2).normal(size=(STEPS_PER_DAY, 4)), -1, 1)
    steps, models = {}, {}
    for csv in (True, False):
        sim = Simulation(SimulationConfig(run_days=1, output_dir=str(tmp_path / f"csv-{csv}"), energyplus_csv=csv))
        try:
            sim.start()
            for a in actions:
                sim.send(a)
                sim.receive()
            episode = sim.episode_dir
        finally:
            sim.close()
        assert (episode / "eplusout.csv").is_file() == csv
        steps[csv] = read_steps(episode)
        models[csv] = (episode / "model.idf").read_text(encoding="latin-1").splitlines()
    pd.testing.assert_frame_equal(steps[True], steps[False])
    changed = [(a, b) for a, b in zip(models[True], models[False], strict=True) if a != b]
    assert [(a.split()[0], b.split()[0]) for a, b in changed] == [("Yes,", "No,")]
    assert "Output CSV" in changed[0][0]


def mean_zone_temps(tmp_path, west: float, east: float) -> tuple[float, float]:
    env = EnergyPlusEnv(weather="CA", model="temp", run_days=1, output_dir=tmp_path)
    try:
        _, _, _ = run_episode(env, np.array([west, east], dtype=np.float32))
        steps = read_steps(env.episode_dir)
    finally:
        env.close()
    late = steps.iloc[len(steps) // 2 :]  # after the zones have settled
    return late["west_temp_c"].mean(), late["east_temp_c"].mean()


@pytest.mark.slow
def test_each_zone_follows_its_own_setpoint(tmp_path, no_leaks):
    # West cold / East warm, then the reverse: each zone must move with its own setpoint only.
    w_lo, e_hi = mean_zone_temps(tmp_path / "a", -0.8, 0.0)  # 14 C vs 25 C supply air
    w_hi, e_lo = mean_zone_temps(tmp_path / "b", 0.0, -0.8)
    assert w_hi - w_lo > 3.0, (w_lo, w_hi)
    assert e_hi - e_lo > 3.0, (e_lo, e_hi)


@pytest.mark.slow
def test_check_env(tmp_path, no_leaks):
    env = EnergyPlusEnv(weather="CA", run_days=1, output_dir=tmp_path)
    try:
        check_env(env, skip_render_check=True)
    finally:
        env.close()


@pytest.mark.slow
def test_two_envs_with_different_weathers_step_alternately(tmp_path, no_leaks):
    a = EnergyPlusEnv(weather="CA", run_days=1, output_dir=tmp_path / "a")
    b = EnergyPlusEnv(weather="FL", run_days=1, output_dir=tmp_path / "b")
    try:
        oa, _ = a.reset()
        ob, _ = b.reset()
        assert a.sim.process.pipes.dir != b.sim.process.pipes.dir
        outdoor_a, outdoor_b = [], []
        done = False
        while not done:
            oa, _, ta, _, ia = a.step(np.zeros(4))
            ob, _, tb, _, ib = b.step(np.zeros(4))
            assert ia["time"] == ib["time"] and ia["weather"] == "CA" and ib["weather"] == "FL"
            outdoor_a.append(oa[0])
            outdoor_b.append(ob[0])
            assert ta == tb
            done = ta
        assert np.mean(outdoor_b) > np.mean(outdoor_a) + 3  # Tampa is warmer than San Francisco in January
    finally:
        a.close()
        b.close()


@pytest.mark.slow
def test_reset_mid_episode_starts_a_fresh_simulation(tmp_path, no_leaks):
    env = EnergyPlusEnv(weather="CA", run_days=1, output_dir=tmp_path)
    try:
        env.reset()
        for _ in range(5):
            env.step(np.zeros(4))
        first = env.sim.proc.pid
        obs, info = env.reset()
        assert env.sim.proc.pid != first and info["time"].hour == 0
        n, _, _ = run_episode(env, np.zeros(4))
        assert n == STEPS_PER_DAY
    finally:
        env.close()
    assert (tmp_path / "episode-000001-CA" / "summary.json").exists()  # the cut episode kept its record


def test_nan_action_raises_value_error(tmp_path, no_leaks):
    env = EnergyPlusEnv(weather="CA", run_days=1, output_dir=tmp_path)
    try:
        env.reset()
        with pytest.raises(ValueError, match="element 1"):
            env.step(np.array([0.0, np.nan, 0.0, 0.0]))
        env.step(np.zeros(4))  # the simulation is unharmed
    finally:
        env.close()


@pytest.mark.slow
def test_time_features_follow_the_clock(no_leaks):
    env = EnergyPlusEnv(weather="CO", run_days=1, time_features=True)
    try:
        obs, info = env.reset(seed=0)
        assert obs.shape == (10,) and env.observation_space.contains(obs)
        assert obs[6:8] == pytest.approx([0.0, 1.0], abs=1e-6)  # 00:00
        for _ in range(6 * 4):  # six hours
            obs, *_, info = env.step(np.zeros(4, dtype=np.float32))
        assert info["time"].hour == 6 and env.observation_space.contains(obs)
        assert obs[6:8] == pytest.approx([1.0, 0.0], abs=1e-6)  # 06:00: a quarter of the day
        assert obs[:6] == pytest.approx([info[name] for name in SENSOR_NAMES], rel=1e-5)
    finally:
        env.close()


@pytest.mark.slow
def test_schedule_features_announce_the_it_load_step_the_next_action_meets(no_leaks):
    env = EnergyPlusEnv(weather="CO", run_days=1, time_features=True, schedule_features=True)
    try:
        obs, info = env.reset(seed=0)
        assert obs.shape == (15,) and env.observation_space.contains(obs)
        it_power = {}
        while info["time"].hour < 6 or info["time"].minute < 15:
            obs, *_, info = env.step(np.zeros(4, dtype=np.float32))
            it_power[info["time"].strftime("%H:%M")] = info["it_power_w"]
            if info["time"].strftime("%H:%M") == "06:00":
                # The IDF's schedule: 0.5 until 06:00, 0.75 until 08:00; the step after 06:00 runs at 0.75.
                assert obs[10:] == pytest.approx([0.75, 0.25, 0.0, 0.25, 2 / 24], abs=1e-6)
        assert obs[10:] == pytest.approx([0.75, 0.25, 0.25 / 24, 0.25, 1.75 / 24], abs=1e-6)
        # ... and the physics agrees: IT power rises in the step the features said would run at 0.75.
        assert it_power["06:15"] > 1.1 * it_power["06:00"]
        assert it_power["06:00"] == pytest.approx(it_power["05:45"], rel=0.01)
    finally:
        env.close()


def _controlled_episode(out: Path, act, **env_kwargs) -> pd.DataFrame:
    """One day on CO under `act(obs, info)`; the step table."""
    env = EnergyPlusEnv(weather="CO", run_days=1, output_dir=out, **env_kwargs)
    try:
        obs, info = env.reset(seed=0)
        terminated = False
        while not terminated:
            obs, _, terminated, _, info = env.step(act(obs, info))
        return read_steps(info["episode_dir"])
    finally:
        env.close()


@pytest.mark.slow
def test_residual_action_corrects_the_rule_based_controller(tmp_path, no_leaks):
    from parallel_eplus.buildings.rules.datacenter import RBCConfig, RuleBasedController

    def records(name: str, residual: float, act) -> pd.DataFrame:
        return _controlled_episode(tmp_path / name, act, residual_scale=residual, rbc_target_c=23.2)

    rbc = records("rbc", 0.0, RuleBasedController(RBCConfig(target_c=23.2)))
    zero = records("zero", 0.2, lambda obs, info: np.zeros(4, np.float32))
    warmer = records("warmer", 0.2, lambda obs, info: np.array([1, 1, 0, 0], np.float32))
    pd.testing.assert_frame_equal(zero, rbc)  # no correction: exactly the rule-based controller
    # +1 on the setpoints adds 0.2 of their half-range (3 C) to whatever the controller asks, never below 10 C
    assert warmer.west_setpoint_c.min() >= 13.0 - 1e-9 and warmer.east_setpoint_c.min() >= 13.0 - 1e-9
    temp_dirs = set(Path(tempfile.gettempdir()).glob("parallel-eplus-episodes-*"))
    with pytest.raises(ValueError, match="four actions"):
        EnergyPlusEnv(model="temp", residual_scale=0.2)
    assert set(Path(tempfile.gettempdir()).glob("parallel-eplus-episodes-*")) == temp_dirs  # refused before any


@pytest.mark.slow
def test_demand_residual_corrects_the_controllers_flow_demand(tmp_path, no_leaks):
    from parallel_eplus.buildings.rules.datacenter import RBCConfig, RuleBasedController

    cfg = RBCConfig(target_c=22.5)
    env = EnergyPlusEnv(residual_scale=1.0, residual_space="demand")
    assert env.action_space.shape == (2,)  # one knob per zone
    env.close()

    def records(name: str, act) -> pd.DataFrame:
        return _controlled_episode(tmp_path / name, act, residual_scale=1.0, residual_space="demand", rbc_target_c=22.5)

    def demand(row: pd.Series, zone: str) -> float:
        """Invert the split range: the flow above the fan's floor, a warmer setpoint below it."""
        setpoint, flow = row[f"{zone}_setpoint_c"], row[f"{zone}_fan_kg_s"]
        if setpoint > cfg.setpoint_floor_c + 1e-9:
            return 1.75 - (setpoint - cfg.setpoint_floor_c) / cfg.setpoint_k_per_kg_s
        return flow

    rbc = _controlled_episode(tmp_path / "rbc", RuleBasedController(cfg), rbc_target_c=22.5)
    zero = records("zero", lambda obs, info: np.zeros(2, np.float32))
    pd.testing.assert_frame_equal(zero, rbc)  # no correction: exactly the rule-based controller
    # The first step's demand, 1 kg/s lower in both zones, wherever it falls on the split range.
    less = records("less", lambda obs, info: np.array([-1, -1], np.float32))
    for zone in ("west", "east"):
        assert demand(less.iloc[0], zone) == pytest.approx(demand(rbc.iloc[0], zone) - 1.0, abs=1e-6)
    # Held, the correction is integrated away: the zones still settle on the controller's target.
    late = less.iloc[len(less) // 2 :]
    assert abs(late.west_temp_c.mean() - 22.5) < 0.3 and abs(late.east_temp_c.mean() - 22.5) < 0.3
    with pytest.raises(ValueError, match="residual space"):
        EnergyPlusEnv(residual_scale=1.0, residual_space="flows")
