"""Reward against hand-computed values; action scaling and checks (no EnergyPlus run needed)."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from parallel_eplus.buildings.datacenter import ACTIONS
from parallel_eplus.buildings.scoring.reward import RewardConfig, reward
from parallel_eplus.engine.actions import scale_action


def test_reward_at_center_is_two_minus_power():
    r, parts = reward((23.5, 23.5), 100_000.0, RewardConfig())
    assert parts == {"reward_comfort": 2.0, "reward_band": 0.0, "reward_power": -1.0}
    assert r == pytest.approx(1.0)


def test_reward_outside_band_hand_computed():
    # West 26 C: Gaussian exp(-0.5 * 2.5^2), 2 K above T_U. East 21 C: exp(-0.5 * 2.5^2), 2 K below T_L.
    g = math.exp(-0.5 * 6.25)
    r, parts = reward((26.0, 21.0), 50_000.0, RewardConfig())
    assert parts["reward_comfort"] == pytest.approx(2 * g)
    assert parts["reward_band"] == pytest.approx(-0.1 * 4.0)
    assert parts["reward_power"] == pytest.approx(-0.5)
    assert r == pytest.approx(2 * g - 0.4 - 0.5)


def test_reward_constants_come_from_config_not_code(tmp_path):
    path = tmp_path / "reward.json"
    path.write_text(json.dumps({"power_weight": 0.0, "center_c": 20.0}))
    cfg = RewardConfig.from_any(path)
    r, _ = reward((20.0, 20.0), 1e6, cfg)
    assert r == pytest.approx(2.0 - 0.1 * 2 * 3.0)  # both zones 3 K below T_L = 23
    with pytest.raises(ValueError, match="unknown reward constant"):
        RewardConfig.from_any({"lambda": 1.0})


def test_action_ranges_are_the_papers():
    assert [(a.low, a.high) for a in ACTIONS] == [(10, 40), (10, 40), (1.75, 7.0), (1.75, 7.0)]
    assert all(len(a.actuators) == 4 for a in ACTIONS[:2])


def test_scaling_and_validation():
    low = np.array([a.low for a in ACTIONS])
    high = np.array([a.high for a in ACTIONS])
    names = tuple(a.name for a in ACTIONS)
    np.testing.assert_allclose(scale_action([-1, 1, 0, 2.0], low, high, names), [10.0, 40.0, 4.375, 7.0])
    np.testing.assert_allclose(scale_action([0.5, -0.5, -1, -5], low, high, names), [32.5, 17.5, 1.75, 1.75])
    with pytest.raises(ValueError, match=r"element 2 \(west_fan_kg_s\) is nan"):
        scale_action([0, 0, float("nan"), 0], low, high, names)
    with pytest.raises(ValueError, match="element 0"):
        scale_action([float("inf"), 0, 0, 0], low, high, names)
    with pytest.raises(ValueError, match="4 elements"):
        scale_action([0, 0], low, high, names)
