"""Comfort as a constraint (`--comfort-target`): the multiplier follows what each batch measured, on real runs."""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest

from parallel_eplus.learning.algorithms import ALGORITHMS
from parallel_eplus.learning.lagrangian import Lagrangian
from parallel_eplus.training.config import ComfortConstraint
from parallel_eplus.training.train import train

from .test_train import scalars, small_config


def _config(tmp_path, name: str, **overrides):
    """The tests' short training: one weather (one template per worker to start, not one per weather), batches of
    384 steps (one two-day episode per worker)."""
    base = dict(weathers=["CA"], batch_size=384, timesteps=768, checkpoint_every=384)
    return small_config(tmp_path, name, **(base | overrides))


def test_the_multiplier_follows_what_each_batch_measured():
    """In log space, by the ratio of samples out of band to those the target allows: up while batches miss the
    target, down as fast when they beat it by as much, within its bounds."""
    lag = Lagrangian.start(ComfortConstraint(target_pct=99.0, multiplier_init=10.0, rate=0.3, floor_pct=0.05))
    lag.update(out=40, zones=1000)  # 96 % in band: 4 % out where 1 % is allowed
    assert lag.measured_pct == pytest.approx(96.0)
    assert lag.multiplier == pytest.approx(10.0 * (4.05 / 1.05) ** 0.3)
    up = lag.multiplier
    lag.update(out=40, zones=1000)  # still short: it keeps rising
    assert lag.multiplier > up
    twice, half = Lagrangian.start(lag.settings), Lagrangian.start(lag.settings)
    twice.update(out=20.5, zones=1000)  # 2.05 % out: with the floor, twice the allowance (1 % + 0.05)
    half.update(out=4.75, zones=1000)  # 0.475 % out: half of it
    assert math.log(twice.multiplier / 10.0) == pytest.approx(-math.log(half.multiplier / 10.0))
    for _ in range(30):  # 100 % in band, batch after batch
        lag.update(out=0, zones=1000)
    assert lag.multiplier == lag.settings.multiplier_min
    held = Lagrangian.start(ComfortConstraint(target_pct=99.0))
    held.update(out=0, zones=0)  # nothing measured (an unoccupied stretch): no change
    assert held.multiplier == held.settings.multiplier_init and held.updates == 0 and math.isnan(held.measured_pct)
    with pytest.raises(ValueError, match="percent"):
        ComfortConstraint(target_pct=100.0).check()


def test_the_cost_counts_the_edges_the_share_in_band_counts():
    """With thermostat bounds (0.2 K of tolerance) a zone held on its bound, as its own thermostat holds it, is in
    band and costs nothing; the cost reaches 1 where the share in band stops counting the zone."""
    from parallel_eplus.buildings.building import load_building

    comfort = load_building("office-small").comfort
    assert comfort.tolerance == pytest.approx(0.2)
    bounds = ((21.0, 24.0),) * 5
    on_bound = (21.0, 24.0, 22.5, 22.5, 22.5)
    assert comfort.cost(on_bound, 0.1, bounds) == (0.0, 0)
    cost, out = comfort.cost((20.85, 22.5, 22.5, 22.5, 22.5), 0.1, bounds)  # halfway into the ramp, still in band
    assert cost == pytest.approx(0.5 / 5) and out == 0
    cost, out = comfort.cost((20.7, 24.3, 22.5, 22.5, 22.5), 0.1, bounds)  # beyond both scored edges
    assert cost == pytest.approx(2 / 5) and out == 2


@pytest.mark.slow
def test_a_missed_target_raises_the_multiplier_and_resume_restores_it(tmp_path, no_leaks):
    """An untrained policy (the paper's initial spread) keeps far fewer than 99.5 % of samples in 22-25 C: each
    batch raises the multiplier. The env pays for energy only; the multiplier is in TensorBoard and checkpoints."""
    cfg = _config(tmp_path, "lag", comfort=ComfortConstraint(target_pct=99.5))
    final = train(cfg, progress=False)
    model = ALGORITHMS["trpo"].load(final, device="cpu")
    lag = model.comfort
    assert lag.updates == 2 and lag.measured_pct < 99.5
    tags = scalars(tmp_path / "tb" / "lag")
    multipliers = [e.value for e in tags["comfort/multiplier"]]
    assert len(multipliers) == 2 and 10.0 < multipliers[0] < multipliers[1] == pytest.approx(lag.multiplier)
    assert [e.value for e in tags["comfort/in_band_pct"]][-1] == pytest.approx(lag.measured_pct)
    steps = pd.read_parquet(next((tmp_path / "runs" / "lag" / "episodes").rglob("steps.parquet")))
    assert (steps["reward_comfort"] == 0).all() and (steps["reward_band"] == 0).all()
    np.testing.assert_allclose(steps["reward"], steps["reward_power"])
    # --resume continues the multiplier where the checkpoint left it
    checkpoint = tmp_path / "runs" / "lag" / "checkpoints" / "model_768_steps.zip"  # the second batch's
    saved = ALGORITHMS["trpo"].load(checkpoint, device="cpu").comfort
    train(_config(tmp_path, "lag", timesteps=1152), resume=checkpoint)
    resumed = ALGORITHMS["trpo"].load(tmp_path / "runs" / "lag" / "model.zip", device="cpu").comfort
    assert resumed.updates == saved.updates + 1  # one batch after the checkpoint, on from its saved state


@pytest.mark.slow
def test_a_target_beaten_lowers_the_multiplier_with_ppo(tmp_path, no_leaks):
    cfg = _config(tmp_path, "lag-low", algorithm="ppo", timesteps=384, comfort=ComfortConstraint(target_pct=1.0))
    train(cfg, progress=False)
    lag = ALGORITHMS["ppo"].load(tmp_path / "runs" / "lag-low" / "model.zip", device="cpu").comfort
    assert lag.updates == 1 and lag.measured_pct > 1.0 and lag.multiplier < 10.0


@pytest.mark.slow
def test_sac_pays_the_multiplier_from_its_replay_buffer(tmp_path, no_leaks):
    from parallel_eplus.training.config import SACSettings

    cfg = _config(tmp_path, "lag-sac", algorithm="sac", timesteps=384, batch_size=192,
                       sac=SACSettings(learning_starts=96, buffer_size=2000),
                       comfort=ComfortConstraint(target_pct=99.5))  # fmt: skip
    train(cfg, progress=False)
    model = ALGORITHMS["sac"].load(tmp_path / "runs" / "lag-sac" / "model.zip", device="cpu")
    model.load_replay_buffer(tmp_path / "runs" / "lag-sac" / "model_replay_buffer.pkl")
    buffer = model.replay_buffer
    assert model.comfort.updates == 2 and model.comfort.multiplier > 10.0
    assert buffer.costs[: buffer.pos].max() > 0  # each transition's cost, stored beside its reward
    buffer.multiplier = model.comfort.multiplier
    np.random.seed(0)
    charged = buffer.sample(64).rewards
    buffer.multiplier = 0.0
    np.random.seed(0)
    plain = buffer.sample(64).rewards
    assert (charged <= plain).all() and (charged < plain).any()
    assert "comfort/multiplier" in scalars(tmp_path / "tb" / "lag-sac")


@pytest.mark.slow
def test_ray_actors_return_the_costs_their_workers_reported(tmp_path, no_leaks):
    cfg = _config(tmp_path, "lag-ray", backend="ray", timesteps=384, comfort=ComfortConstraint(target_pct=99.5))
    train(cfg, progress=False)
    lag = ALGORITHMS["trpo"].load(tmp_path / "runs" / "lag-ray" / "model.zip", device="cpu").comfort
    assert lag.updates == 1 and 0.0 <= lag.measured_pct < 99.5 and lag.multiplier > 10.0
