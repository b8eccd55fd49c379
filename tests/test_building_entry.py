"""Entry points take a building spec: gymnasium ids, `simulate --building`, the spec's weather names."""

from __future__ import annotations

from pathlib import Path

import gymnasium as gym
import numpy as np
import pandas as pd
import pytest

import parallel_eplus
from parallel_eplus.buildings import datacenter as model
from parallel_eplus.cli import main
from parallel_eplus.envs.env import EnergyPlusEnv

SPECS = Path(model.__file__).parent / "specs"


def _elsewhere(text: str) -> str:
    """A built-in spec's text for a file outside the package: its models named by absolute path."""
    from parallel_eplus.buildings.resources import model_file

    for key in ("idf", "baseline_idf"):
        name = text.split(f'\n{key} = "', 1)[1].split('"', 1)[0]
        text = text.replace(f'{key} = "{name}"', f'{key} = "{model_file(name)}"', 1)
    return text


@pytest.mark.slow
def test_building_env_matches_model_variant(tmp_path, no_leaks):
    """The setpoint-only spec through `Building-v0` steps exactly as the built-in `temp` variant."""
    spec = SPECS / "datacenter-2zone-temp.toml"
    env = gym.make(parallel_eplus.BUILDING_ENV_ID, building=spec, weather="CA", run_days=1, output_dir=tmp_path / "a")
    ref = EnergyPlusEnv(weather="CA", model="temp", run_days=1, output_dir=tmp_path / "b")
    try:
        assert env.action_space.shape == (2,) and env.observation_space.shape == (6,)
        a, _ = env.reset()
        b, _ = ref.reset()
        np.testing.assert_array_equal(a, b)
        for action in np.linspace(-1, 1, 8, dtype=np.float32):
            a, ra, *_ = env.step(np.array([action, -action], np.float32))
            b, rb, *_ = ref.step(np.array([action, -action], np.float32))
            np.testing.assert_array_equal(a, b)
            assert ra == rb
    finally:
        env.close()
        ref.close()


@pytest.mark.slow
def test_spec_weather_short_name(tmp_path, no_leaks):
    """A short name only the spec knows resolves through it."""
    text = _elsewhere((SPECS / "datacenter-2zone.toml").read_text())
    spec = tmp_path / "dc.toml"
    spec.write_text(text.replace("\nCA = ", "\nSFO = "))
    env = gym.make("parallel_eplus/DataCenter-v0", building=spec, weather="SFO", run_days=1, output_dir=tmp_path / "e")
    try:
        env.reset()
        env.step(np.zeros(4, np.float32))
    finally:
        env.close()


@pytest.mark.slow
def test_simulate_building(tmp_path, capsys, no_leaks):
    spec = SPECS / "datacenter-2zone.toml"
    assert main(["simulate", "--building", str(spec), "--days", "1", "--quiet"]) == 0
    assert "power" in capsys.readouterr().out.lower()


@pytest.mark.slow
def test_evaluate_building_baseline(tmp_path, no_leaks):
    """`evaluate --building` runs the spec's built-in controls; its summary uses the spec's reward signals."""
    from parallel_eplus.evaluation.controllers import BASELINE_LABEL, Controller
    from parallel_eplus.evaluation.sweep import run_sweep

    spec = SPECS / "datacenter-2zone.toml"
    df = run_sweep([Controller(BASELINE_LABEL, "baseline")], ["CA"], 1, 1, tmp_path, progress=False, building=spec)
    ref = run_sweep([Controller(BASELINE_LABEL, "baseline")], ["CA"], 1, 1, tmp_path / "ref", progress=False)
    assert df["power_kw"].tolist() == ref["power_kw"].tolist()
    assert df["in_band_pct"].tolist() == ref["in_band_pct"].tolist()


def test_evaluate_refuses_other_building(tmp_path):
    from parallel_eplus.evaluation.controllers import Controller
    from parallel_eplus.evaluation.sweep import run_sweep

    policy = Controller("p", "policy", tmp_path / "model.zip", building=None)
    with pytest.raises(ValueError, match="trained on building datacenter-2zone"):
        run_sweep([policy], ["CA"], 1, 1, tmp_path, progress=False, building=SPECS / "datacenter-2zone-temp.toml")


@pytest.mark.slow
def test_evaluate_generic_building_cli(tmp_path, no_leaks):
    """A spec with its own names: evaluate reports power and % in band per temperature against its baseline."""
    text = _elsewhere((SPECS / "datacenter-2zone.toml").read_text())
    text = text.replace("west_temp_c", "zone_a").replace("east_temp_c", "zone_b").replace('"power_w"', '"total_w"')
    spec = tmp_path / "generic.toml"
    spec.write_text(text.replace('name = "power_w"', 'name = "total_w"'))
    out = tmp_path / "eval"
    argv = ["evaluate", "--building", str(spec), "--baseline", "--weathers", "CA", "--run-days", "1"]
    assert main([*argv, "--workers", "1", "--out", str(out), "--quiet"]) == 0
    table = (out / "results.md").read_text()
    assert "zone_a in 22–25 °C" in table and "zone_b in 22–25 °C" in table
    df = pd.read_csv(out / "results.csv")
    assert df["power_kw"].iloc[0] > 0 and 0 <= df["zone_a_in_band_pct"].iloc[0] <= 100
