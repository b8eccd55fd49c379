"""The data center's behaviour on a fixed action sequence is frozen in tests/data (recorded before the building
moved into a spec file); the same actions must give identical observations, rewards and power."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from parallel_eplus.buildings import datacenter as model
from parallel_eplus.envs.env import EnergyPlusEnv

FIXTURE = Path(__file__).parent / "data" / "datacenter_2zone_ca_2days.csv"
SPEC = Path(model.__file__).parent / "specs" / "datacenter-2zone.toml"


@pytest.mark.slow
def test_fixed_actions_reproduce_fixture(tmp_path, no_leaks):
    _replay(EnergyPlusEnv(weather="CA", model="temp_fan", run_days=2, output_dir=tmp_path))


@pytest.mark.slow
def test_spec_file_reproduces_fixture(tmp_path, no_leaks):
    """The spec given explicitly: both sides of the pipe (env and EnergyPlus callback) build from the file."""
    _replay(EnergyPlusEnv(weather="CA", building=SPEC, run_days=2, output_dir=tmp_path))


def _replay(env: EnergyPlusEnv) -> None:
    expected = pd.read_csv(FIXTURE, comment="#")
    action_cols = [c for c in expected.columns if c.startswith("action")]
    obs_cols = [c for c in expected.columns if c not in ("step", "reward", *action_cols)]
    rows = []
    try:
        env.reset()
        for actions in expected[action_cols].to_numpy(np.float32):
            obs, reward, terminated, _, _ = env.step(actions)
            rows.append([*np.asarray(obs, float), float(reward)])
    finally:
        env.close()
    assert terminated
    got = pd.DataFrame(rows, columns=[*obs_cols, "reward"])
    np.testing.assert_array_equal(got[obs_cols].to_numpy(), expected[obs_cols].to_numpy())
    np.testing.assert_array_equal(got["reward"].to_numpy(), expected["reward"].to_numpy())
