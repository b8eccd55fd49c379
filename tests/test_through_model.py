"""A policy learned through the planner's model (learning/model_based/students/through_model.py), from real states of a
short EnergyPlus run of the paper's data center: the rollouts branch from those states and stay within the data's
support, and gradient steps on the planner's cost lower it."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import torch as th
from sb3_contrib import TRPO

from parallel_eplus.buildings.building import load_building
from parallel_eplus.envs.env import EnergyPlusEnv
from parallel_eplus.learning.model_based.control.mpc import MPC
from parallel_eplus.learning.model_based.model.exogenous import model_schedule
from parallel_eplus.learning.model_based.students.through_model import Clock, Rollouts, Starts, train, widen
from parallel_eplus.learning.saved_models import load_model
from parallel_eplus.runs.norm_stats import read_stats
from parallel_eplus.runs.policy_files import normalization_file

ROOT = Path(__file__).resolve().parents[1]
RUN = ROOT / "results/model-based/datacenter-2zone/runs/datacenter-2zone-mpc-seed0"  # committed: planner + policy


def test_a_policy_learns_the_planners_cost_through_the_model_from_real_states(tmp_path, no_leaks):
    th.set_num_threads(1)  # as training sets it: the cores belong to EnergyPlus
    mpc = MPC.load(RUN / "best/planner/planner.pt")
    building = load_building(mpc.building)
    narrow = load_model(TRPO, RUN / "model.zip", device="cpu")
    clock = Clock(time=True, schedule=model_schedule(mpc.building))
    before_widening = read_stats(normalization_file(RUN / "model.zip"))
    model, stats = widen(narrow, before_widening, clock, building)
    th.manual_seed(0)
    rollouts = Rollouts(mpc, building, stats, model.policy, clock)

    # A day of the widened policy in EnergyPlus, the time and schedule features in its observation.
    env = EnergyPlusEnv(weather="CA", model="temp_fan", run_days=1, time_features=True, schedule_features=True,
                        output_dir=tmp_path)  # fmt: skip
    starts = Starts()
    try:
        obs, info = env.reset()
        prev = mpc.initial.copy()
        for _ in range(48):
            with th.no_grad():
                wide = rollouts.act(th.as_tensor(obs[None]))[0].numpy()
                old = narrow.policy.predict(before_widening.normalize_obs(obs[None, :6]), deterministic=True)[0][0]
            # the new inputs start at zero weight: the widened policy acts as the distilled one
            np.testing.assert_allclose(np.clip(wide, -1, 1), old, atol=1e-5)
            starts.add(obs, prev, info["time"], info["weather"])
            prev = np.clip(wide, -1, 1).astype(np.float32)
            obs, _, terminated, truncated, info = env.step(prev)
            assert not (terminated or truncated)
    finally:
        env.close()

    for o, t in zip(starts.obs, starts.times, strict=True):  # the clock rebuilds the env's own features
        np.testing.assert_allclose(clock(t), o[6:], atol=1e-6)

    # The rollouts branch from the real states: the first step acts on the real observation; every member's every
    # action lies within the planner's support.
    b = rollouts.batch(starts, np.arange(len(starts)))
    with th.no_grad():
        before, _ = rollouts.cost(b, comfort_weight=1.0)
        first = th.maximum(th.minimum(rollouts.act(b["obs"]), rollouts.high), rollouts.low)
    assert len(rollouts.applied) == mpc.settings.horizon
    for member in rollouts.applied[0]:
        np.testing.assert_allclose(member.numpy(), first.numpy(), rtol=1e-6)
    for a in rollouts.applied:
        assert bool(((a >= rollouts.low) & (a <= rollouts.high)).all())

    # Gradient steps on the planner's cost lower it on these states.
    params = list(model.policy.mlp_extractor.policy_net.parameters()) + list(model.policy.action_net.parameters())
    train(rollouts, starts, th.optim.Adam(params, lr=1e-3), 60, 48, 1.0, np.random.default_rng(0))
    with th.no_grad():
        after, parts = rollouts.cost(b, comfort_weight=1.0)
    assert float(after) < 0.9 * float(before), (float(before), float(after), parts)
