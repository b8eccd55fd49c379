"""Weather that varies per episode, forecasts as observations, and the wheel's 16 climates (docs/weather.md)."""

from __future__ import annotations

import datetime as dt
import json
from importlib import resources
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from parallel_eplus.buildings.weather.epw import HEADER_LINES, read_epw
from parallel_eplus.buildings.weather.files import ALL_WEATHERS, parse_weathers, resolve_weather, weather_label
from parallel_eplus.buildings.weather.forecast_features import (
    Forecaster,
    ForecastSpec,
    ar1_temperature_error,
    outdoor_forecast,
)
from parallel_eplus.buildings.weather.noise import ou_noise, parse_noise, perturb_epw

CA = resolve_weather("CA")


def _acf(x: np.ndarray, lag: int) -> float:
    x = x - x.mean()
    return float(np.dot(x[:-lag], x[lag:]) / np.dot(x, x))


@pytest.mark.parametrize("sigma, mu, tau", [(1.0, 0.0, 24.0), (2.0, 0.5, 12.0)])
def test_ou_noise_has_the_asked_sigma_mean_and_correlation_time(sigma, mu, tau):
    """Over 20 independent years: standard deviation sigma, mean mu, autocorrelation exp(-1) at lag tau."""
    rng = np.random.default_rng(0)
    years = np.stack([ou_noise(8760, sigma, mu, tau, rng) for _ in range(20)])
    assert years.std() == pytest.approx(sigma, rel=0.05)
    assert years.mean() == pytest.approx(mu, abs=0.1 * sigma)
    acf = np.mean([_acf(y, int(tau)) for y in years])
    assert acf == pytest.approx(np.exp(-1), abs=0.05)
    assert -int(tau) / np.log(acf) == pytest.approx(tau, rel=0.15)  # tau recovered from the data
    assert np.mean([_acf(y, 1) for y in years]) == pytest.approx(np.exp(-1 / tau), abs=0.02)


def test_a_written_epw_carries_the_noise_and_nothing_else(tmp_path):
    """One year on a written file: the dry bulb's change has sigma and tau within tolerance; the header and every
    column but the dry bulb and (where the dry bulb fell below it) the dew point are byte for byte the file's."""
    params = perturb_epw(CA, tmp_path / "a.epw", parse_noise("drybulb=1:0:24"), seed=3)
    assert params == {"noise_drybulb_sigma": 1.0, "noise_drybulb_mu": 0.0, "noise_drybulb_tau_h": 24.0}
    old, new = CA.read_text().splitlines(True), (tmp_path / "a.epw").read_text().splitlines(True)
    assert new[:HEADER_LINES] == old[:HEADER_LINES] and len(new) == len(old) == HEADER_LINES + 8760
    for a, b in zip(old[HEADER_LINES:], new[HEADER_LINES:], strict=True):
        fa, fb = a.split(","), b.split(",")
        assert fa[:6] + fa[8:] == fb[:6] + fb[8:] and b.endswith("\n") and len(fb) == 35
        assert float(fb[7]) <= float(fb[6])  # the dew point never above the dry bulb
    _, before = read_epw(CA)
    _, after = read_epw(tmp_path / "a.epw")
    change = (after.drybulb - before.drybulb).to_numpy()
    assert change.std() == pytest.approx(1.0, rel=0.2)  # one year: ~180 independent samples at tau 24 h
    assert _acf(change, 24) == pytest.approx(np.exp(-1), abs=0.15)
    assert (tmp_path / "a.epw").read_bytes() != CA.read_bytes()
    perturb_epw(CA, tmp_path / "b.epw", parse_noise("drybulb=1:0:24"), seed=3)
    perturb_epw(CA, tmp_path / "c.epw", parse_noise("drybulb=1:0:24"), seed=4)
    assert (tmp_path / "b.epw").read_bytes() == (tmp_path / "a.epw").read_bytes()  # same seed, same year
    assert (tmp_path / "c.epw").read_bytes() != (tmp_path / "a.epw").read_bytes()


def test_ranges_are_drawn_per_episode_and_values_clipped(tmp_path):
    noise = parse_noise("relhum=5..20:0..5:6..48,dirnorrad=200")
    drawn = [perturb_epw(CA, tmp_path / f"{s}.epw", noise, seed=s) for s in range(3)]
    assert len({d["noise_relhum_sigma"] for d in drawn}) == 3
    assert all(5 <= d["noise_relhum_sigma"] <= 20 and 6 <= d["noise_relhum_tau_h"] <= 48 for d in drawn)
    _, before = read_epw(CA)
    _, after = read_epw(tmp_path / "0.epw")
    assert after.relhum.between(0, 100).all() and (after.dirnorrad >= 0).all()
    assert (after.dirnorrad[before.dirnorrad == 0] == 0).all()  # no sun at night
    assert (after.dewpoint != before.dewpoint).any()  # the moisture EnergyPlus reads follows the humidity


@pytest.mark.parametrize(
    "text, match",
    [("windspd=1", "cannot be perturbed"), ("drybulb=x", "not a number"), ("drybulb=2..1", "downwards"),
     ("drybulb=1:0:0", "tau"), ("drybulb", "SIGMA")],
)  # fmt: skip
def test_a_malformed_noise_option_says_what_is_wrong(text, match):
    with pytest.raises(ValueError, match=match):
        parse_noise(text)
    assert parse_noise(None) is None and parse_noise("default").columns["drybulb"].sigma == (1.0, 1.0)


def test_a_forecast_is_the_files_values_ahead_clipped_at_the_run_periods_end():
    _, data = read_epw(CA)
    drybulb = data.drybulb.to_numpy()
    f = Forecaster((outdoor_forecast(6),), CA, 365, 4, seed=0)
    # at 10:00 on Jan 2 (34 h into the year), hour k ahead is the record ending at hour 34 + k (index 33 + k)
    assert f(dt.datetime(2013, 1, 2, 10)) == pytest.approx(drybulb[34:40])
    at_1015 = f(dt.datetime(2013, 1, 2, 10, 15))  # between records: linear, as EnergyPlus interpolates
    assert at_1015[0] == pytest.approx(0.75 * drybulb[34] + 0.25 * drybulb[35])
    late = f(dt.datetime(2013, 12, 31, 21))  # 3 hours before the year ends: the last value repeats
    assert late == pytest.approx([*drybulb[-3:], drybulb[-1], drybulb[-1], drybulb[-1]])
    day = Forecaster((ForecastSpec("x", "drybulb", 4, 2, in_steps=True),), CA, 1, 4, seed=0)  # 30-min stride
    assert day(dt.datetime(2013, 1, 1, 23)) == pytest.approx([*np.interp([23.5, 24], [23, 24], drybulb[22:24]),
                                                              drybulb[23], drybulb[23]])  # fmt: skip
    # a run of 2 days from July 1 (day 182; a test period's, or a random start's) ends at hour 183 x 24, not 48
    july = Forecaster((outdoor_forecast(6),), CA, 2, 4, seed=0, start_day=182)
    assert july(dt.datetime(2013, 7, 1, 10)) == pytest.approx(drybulb[181 * 24 + 10 : 181 * 24 + 16])
    assert july(dt.datetime(2013, 7, 2, 21))[-1] == pytest.approx(drybulb[183 * 24 - 1])


def test_forecast_error_is_zero_when_off_and_seeded_when_on():
    _, data = read_epw(CA)
    t = dt.datetime(2013, 3, 1, 12)
    exact = Forecaster((outdoor_forecast(24),), CA, 365, 4, seed=0)(t)
    assert exact == Forecaster((outdoor_forecast(24),), CA, 365, 4, seed=99)(t)  # no error: the seed is unused
    low = Forecaster((outdoor_forecast(24, "low"),), CA, 365, 4, seed=1)
    high = Forecaster((outdoor_forecast(24, "high"),), CA, 365, 4, seed=1)
    assert low(t) == Forecaster((outdoor_forecast(24, "low"),), CA, 365, 4, seed=1)(t)
    assert low(t) != pytest.approx(exact) and high(t) != pytest.approx(low(t))
    assert low(t + dt.timedelta(minutes=15)) != low(t) and low(t) == low(t)  # redrawn only when the hour changes
    rng = np.random.default_rng(0)  # BOPTEST's high level: the error's first hour ~ N(-0.58, 1.5), then AR(1) 0.95
    errors = np.array([ar1_temperature_error(24, "high", rng) for _ in range(2000)])
    assert errors[:, 0].mean() == pytest.approx(-0.58, abs=0.1) and errors[:, 0].std() == pytest.approx(1.5, rel=0.1)
    assert errors[:, 23].std() > errors[:, 0].std()  # it grows along the horizon
    with pytest.raises(ValueError, match="error"):
        ForecastSpec("x", "windspd", 3, error="low")


def test_a_spec_observation_can_be_a_forecast(tmp_path):
    from parallel_eplus.buildings.building import load_building
    from parallel_eplus.buildings.datacenter import AGENT_IDF, BASELINE_IDF
    from parallel_eplus.buildings.spec.load import SpecError, load_spec
    from parallel_eplus.envs.env import observation_space

    text = (Path(load_building().spec.path)).read_text()
    for idf in (AGENT_IDF, BASELINE_IDF):  # bare names are for the built-in specs only
        text = text.replace(f'"{idf.name}"', json.dumps(str(idf)))
    extra = '\n[[observations]]\nname = "outdoor_next"\nforecast = "drybulb"\nhours = 3\nerror = "medium"\n'
    spec = tmp_path / "dc.toml"
    spec.write_text(text.replace("[[actions]]", extra + "\n[[actions]]", 1))
    loaded = load_spec(spec)
    assert [o.name for o in loaded.observations] == list(load_building().sensor_names)  # EnergyPlus reads these
    assert loaded.forecasts == (ForecastSpec("outdoor_next", "drybulb", 3, 1.0, False, "medium"),)
    assert observation_space(building=spec, forecast_hours=2).shape == (6 + 3 + 2,)
    spec.write_text(text.replace("[[actions]]", extra.replace("hours", "hour") + "\n[[actions]]", 1))
    with pytest.raises(SpecError, match="hours or steps"):
        load_spec(spec)


def test_every_climate_the_wheel_ships_has_a_short_name():
    names = parse_weathers("all")
    assert len(names) == len(ALL_WEATHERS) == 16 and names[:5] == ["CA", "CO", "FL", "IL", "VA"]
    files = {resolve_weather(n) for n in names}
    shipped = Path(str(resources.files("pyenergyplus") / "data" / "weather")).glob("*.epw")
    assert len(files) == 16 and {f.name for f in files} == {f.name for f in shipped}
    assert [weather_label(w) for w in ("las vegas", "Chicago", "phoenix", "ca")] == ["LasVegas", "IL", "Phoenix", "CA"]


@pytest.mark.slow
def test_episodes_seeded_alike_see_the_same_weather_and_the_forecast_reads_it(tmp_path, no_leaks):
    """Real EnergyPlus: the outdoor temperature it recorded differs between seeds and repeats for one seed; the
    forecast observation, and the planner's future weather (model-based control), are the episode's own
    (perturbed) file, hour by hour."""
    from parallel_eplus.envs.env import EnergyPlusEnv
    from parallel_eplus.learning.model_based.model.exogenous import Forecasts

    env = EnergyPlusEnv(run_days=1, weather_noise="drybulb=3:0:24", forecast_hours=4, output_dir=tmp_path)
    outdoor, forecasts, planned, planner = {}, {}, {}, Forecasts(None)
    try:
        for run, seed in enumerate((1, 2, 1)):
            obs, info = env.reset(seed=seed)
            assert obs.shape == (10,) and env.observation_space.contains(obs)
            while True:
                if info["time"].minute == 0:
                    forecasts[run, info["time"].hour] = obs[6:].copy()
                    ahead = [info["time"] + dt.timedelta(hours=k) for k in range(1, 5)]
                    planned[run, info["time"].hour] = planner.of(info).at(ahead)[:, 0]
                obs, _, terminated, _, info = env.step(np.zeros(4, dtype=np.float32))
                if terminated:
                    break
            steps = pd.read_parquet(Path(info["episode_dir"]) / "steps.parquet")
            outdoor[run] = steps["outdoor_temp_c"].to_numpy()
            summary = json.loads((Path(info["episode_dir"]) / "summary.json").read_text())
            assert summary["weather_seed"] == seed and summary["noise_drybulb_sigma"] == 3.0
            _, epw = read_epw(Path(info["episode_dir"]) / CA.name)
            for hour in range(6, 20):  # hour k ahead: the record ending at hour + k, clipped at the day's end
                ahead = [epw.drybulb[min(hour + k, 24) - 1] for k in range(1, 5)]
                assert forecasts[run, hour] == pytest.approx(ahead, abs=1e-4)
                assert planned[run, hour] == pytest.approx(ahead, abs=1e-4)
            assert info["weather_file"] == str(Path(info["episode_dir"]) / CA.name)
            _, named = read_epw(CA)
            assert np.abs(np.array(named.drybulb[:24]) - epw.drybulb[:24]).max() > 0.5  # not the named file
    finally:
        env.close()
    assert np.array_equal(outdoor[0], outdoor[2])
    assert np.abs(outdoor[0] - outdoor[1]).max() > 0.5


@pytest.mark.slow
def test_a_policy_trained_with_noise_and_forecast_is_scored_on_noisy_years(tmp_path, no_leaks):
    """`train --weather-noise --forecast 3`: the episodes' noise goes to episodes.csv, the policy records its
    forecast, and `evaluate --weather-noise --noisy-years 2` runs each controller on the same two noisy years."""
    from parallel_eplus.evaluation.controllers import BASELINE_LABEL, Controller, policy_controller
    from parallel_eplus.evaluation.seeds import seed_table
    from parallel_eplus.evaluation.sweep import run_sweep
    from parallel_eplus.runs.policy_files import policy_features
    from parallel_eplus.training.config import TrainConfig
    from parallel_eplus.training.train import train

    cfg = TrainConfig(
        workers=1, weathers=["CA"], run_days=1, timesteps=96, batch_size=96, run_name="noisy", seed=5,
        weather_noise="drybulb=0.5..2", forecast_hours=3, runs_dir=str(tmp_path / "runs"),
        tensorboard_dir=str(tmp_path / "tb"),
    )  # fmt: skip
    final = train(cfg, progress=False)
    episodes = pd.read_csv(final.parent / "episodes.csv")
    assert episodes["noise_drybulb_sigma"].between(0.5, 2).all() and episodes["weather_seed"].notna().all()
    policy = policy_controller(str(final))
    assert policy.forecast_hours == 3 and policy_features(final) == (False, False)
    controllers = [Controller(BASELINE_LABEL, "baseline"), policy]
    df = run_sweep(controllers, ["Miami"], 1, 2, tmp_path / "eval", progress=False, weather_noise="default",
                   noisy_years=2)  # fmt: skip
    assert sorted(df["run"]) == ["noisy year 0", "noisy year 1", "year 0", "year 1"]
    assert set(df["weather"]) == {"Miami"} and (df["steps"] == 96).all()
    table = seed_table(df, BASELINE_LABEL)
    assert set(table["controller"]) == {BASELINE_LABEL, policy.label} and table["runs"].max() == 2
