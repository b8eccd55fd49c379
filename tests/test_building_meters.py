"""Observations from meters and scaled variables: resolved by the check, read by the engine, in W (real runs)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from parallel_eplus.buildings import datacenter as model
from parallel_eplus.buildings.check.names import check_building
from parallel_eplus.buildings.resources import model_file
from parallel_eplus.buildings.spec.load import SpecError
from parallel_eplus.envs.env import EnergyPlusEnv

CRAC = (Path(model.__file__).parent / "specs" / "datacenter-crac.toml").read_text()

EXTRA = """
[[observations]]
name = "hvac_meter_w"
meter = "{meter}"
low = 0.0
high = 1e9

[[observations]]
name = "hvac_kw"
variable = "Facility Total HVAC Electricity Demand Rate"
key = "Whole Building"
scale = 0.001
low = 0.0
high = 1e6

[[actions]]"""


def _spec(tmp_path: Path, meter: str, timestep_meter: bool = False) -> Path:
    """The CRAC's spec outside the package (its models by absolute path), with a meter and a scaled variable;
    `timestep_meter`: its agent model asks EnergyPlus to report the meter every timestep, to compare against."""
    text = CRAC
    for key in ("idf", "baseline_idf"):
        name = text.split(f'\n{key} = "', 1)[1].split('"', 1)[0]
        text = text.replace(f'{key} = "{name}"', f'{key} = "{model_file(name)}"', 1)
    if timestep_meter:
        agent = model_file(CRAC.split('\nidf = "', 1)[1].split('"', 1)[0])
        idf = tmp_path / agent.name
        idf.write_text(
            agent.read_text(encoding="latin-1") + f"\n  Output:Meter,{meter},Timestep;\n", encoding="latin-1"
        )
        text = text.replace(f'idf = "{agent}"', f'idf = "{idf}"', 1)
    path = tmp_path / f"crac-{meter.replace(':', '-')}.toml"
    path.write_text(text.replace("\n[[actions]]", EXTRA.format(meter=meter), 1))
    return path


def _reported(eso: Path, meter: str) -> list[float]:
    """A meter's timestep values as EnergyPlus wrote them (J), from its .eso."""
    lines = eso.read_text().splitlines()
    code = next(ln.split(",")[0] for ln in lines if f",{meter} [J] !TimeStep" in ln)
    data = lines[lines.index("End of Data Dictionary") + 1 :]
    return [float(ln.split(",")[1]) for ln in data if ln.split(",")[0] == code]


def test_a_meter_is_observed_as_its_rate(tmp_path, no_leaks):
    """Electricity:HVAC is observed as its joules per 10-minute step over 600 s, the very values EnergyPlus
    reports for the meter each timestep; `scale` multiplies a variable (W to kW)."""
    spec = _spec(tmp_path, "Electricity:HVAC", timestep_meter=True)
    check_building(spec, use_cache=False)
    env = EnergyPlusEnv(building=spec, weather="CA", run_days=1, output_dir=tmp_path / "run")
    rng = np.random.default_rng(0)
    try:
        obs, info = env.reset()
        assert env.observation_space.shape == (8,)
        terminated = False
        while not terminated:  # changing actions: EnergyPlus splits timesteps, where a rate variable is not the mean
            obs, _, terminated, _, info = env.step(rng.uniform(-1, 1, 2).astype(np.float32))
            assert obs[6] == np.float32(info["hvac_meter_w"])  # at the spec's position in the observation
            assert info["hvac_kw"] == pytest.approx(info["hvac_power_w"] / 1000, rel=1e-12)
        steps = pd.read_parquet(Path(info["episode_dir"]) / "steps.parquet")
    finally:
        env.close()
    reported = np.array(_reported(Path(info["episode_dir"]) / "eplusout.eso", "Electricity:HVAC"))
    assert len(steps) == len(reported) == 144 and reported.min() > 0
    np.testing.assert_allclose(steps["hvac_meter_w"], reported / 600, rtol=1e-9)


def test_check_names_the_meter(tmp_path):
    with pytest.raises(SpecError, match=r'observations\[6\]: no meter "Electricity:HVACC"; close: "Electricity:HVAC"'):
        check_building(_spec(tmp_path, "Electricity:HVACC"), use_cache=False)
    with pytest.raises(SpecError, match="Facility Total Electricity Demand Rate"):  # 25.2 gives no handle to it
        check_building(_spec(tmp_path, "Electricity:Facility"), use_cache=False)
