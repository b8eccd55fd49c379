"""`train --algorithm mbpo` on real short episodes: SAC on real steps and the ensemble's rollouts, started from a
planner run's model and data; the rollouts, the multiplier on them, a Ctrl-C and the resume."""

from __future__ import annotations

import json
import os
import signal
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from parallel_eplus.deploy.export.policy import export
from parallel_eplus.learning.algorithms import ALGORITHMS
from parallel_eplus.learning.model_based.mbpo import algorithm as mbpo
from parallel_eplus.learning.model_based.mbpo import state as mbpo_state
from parallel_eplus.learning.model_based.mbpo.buffer import ModelMixBuffer
from parallel_eplus.learning.model_based.settings import MBPOSettings, MPCSettings
from parallel_eplus.runs.policy_files import load_policy
from parallel_eplus.training.config import ComfortConstraint, SACSettings, TrainConfig
from parallel_eplus.training.train import train

from .test_model_based import mpc_config
from .test_train import scalars

ROLLOUTS = MBPOSettings(rollout_length=2, rollout_batch=64, rollout_every=48, gradient_steps=1, pretrain_updates=200)


def mbpo_config(root: Path, name: str, planner: Path | None, **overrides) -> TrainConfig:
    base = dict(
        algorithm="mbpo", workers=2, weathers=["CA", "FL"], run_days=1, timesteps=384, checkpoint_every=192,
        batch_size=192,  # the multiplier's update period
        run_name=name, runs_dir=str(root / "runs"), tensorboard_dir=str(root / "tb"), mbpo=ROLLOUTS,
        init_from=None if planner is None else str(planner), comfort=ComfortConstraint(target_pct=99.0),
        mpc=MPCSettings(refit_every=192, refit_epochs=2), sac=SACSettings(batch_size=64, buffer_size=5000),
    )  # fmt: skip
    base.update(overrides)
    return TrainConfig(**base)


@pytest.fixture(scope="module")
def planner_run(tmp_path_factory) -> Path:
    root = tmp_path_factory.mktemp("planner")
    settings = MPCSettings(explore_steps=96, refit_every=192, epochs=10, candidates=64, distill=False, record_days=1)
    train(mpc_config(root, "planner", run_days=1, timesteps=288, mpc=settings), progress=False)
    return root / "runs" / "planner"


@pytest.mark.slow
def test_rollouts_branch_from_real_states_within_the_datas_support_and_pay_the_multiplier(planner_run, tmp_path,
                                                                                          no_leaks):  # fmt: skip
    final = train(mbpo_config(tmp_path, "mb", planner_run), progress=False)
    run = final.parent
    model = ALGORITHMS["mbpo"].load(final, device="cpu")
    model.load_replay_buffer(run / "model_replay_buffer.pkl")
    buffer = model.replay_buffer
    assert isinstance(buffer, ModelMixBuffer)
    # two generations before the first real step (100 updates each), then one every 48 steps; 64 branches x 2 steps
    assert buffer.model_rows() == (2 + 384 // 48) * 64 * 2, buffer.model_rows()
    ensemble, data, starts = mbpo_state.load_state(run / mbpo_state.STATE_DIR, 1, 0)
    planner_starts = mbpo_state.from_planner_run(planner_run, 1, 0)[2]
    assert len(starts) >= len(planner_starts) + 384 - 2 * 2  # the planner's states, then every real step
    real = np.stack(starts.obs)
    first = buffer.m_obs[:64]  # the first generation's first steps: states the planner saw, as they were
    assert all(np.any(np.all(real == row, axis=1)) for row in first)
    second = buffer.m_obs[64:128]  # their second steps: rebuilt from the model's prediction, not copies
    assert not any(np.any(np.all(real == row, axis=1)) for row in second)
    low, high = ensemble.support
    acts = buffer.m_act[: buffer.model_rows()]
    assert np.all(acts >= low - 1e-6) and np.all(acts <= high + 1e-6)
    temps = buffer.m_next[: buffer.model_rows(), 1:3]  # the zones the model predicted: where the real ones went
    seen = real[:, 1:3]
    assert np.all((temps >= seen.min() - 5) & (temps <= min(seen.max() + 5, 50))), (temps.min(), temps.max())
    assert len(data) > len(mbpo_state.from_planner_run(planner_run, 1, 0)[1])  # SAC's real steps joined its data

    # The multiplier charges the model's transitions as it does the real ones.
    assert buffer.m_cost[: buffer.model_rows()].max() > 0
    buffer.real_ratio = 0.0
    buffer.multiplier = 0.0
    np.random.seed(0)
    plain = buffer.sample(256).rewards
    buffer.multiplier = 50.0
    np.random.seed(0)
    charged = buffer.sample(256).rewards
    assert (charged <= plain).all() and (charged < plain).any()
    assert model.comfort.updates >= 1

    act = load_policy(final)  # an SAC policy: `export` takes it as any policy (its closed-loop parity: test_deploy)
    assert act(real[:3]).shape == (3, 4)
    contract = json.loads(export(final, tmp_path / "controller").read_text())
    assert contract["policy"]["algorithm"] == "mbpo" and contract["export_check"]["max_abs_diff"] <= 1e-5


@pytest.mark.slow
def test_a_run_interrupted_resumes_with_its_model_and_replay_buffer(tmp_path, monkeypatch, no_leaks, caplog):
    """From scratch: the building's own controls recorded and fitted first; Ctrl-C; the resume keeps both."""
    cfg = mbpo_config(tmp_path, "cut", None, timesteps=10_000, mbpo=MBPOSettings(**{**ROLLOUTS.__dict__,
                      "record_days": 1}))  # fmt: skip
    on_step, hit = mbpo.ModelRollouts._on_step, []

    def ctrl_c_at_step_250(self):  # Ctrl-C, as the terminal sends it, once past the first checkpoint
        if self.num_timesteps >= 250 and not hit:
            hit.append(self.num_timesteps)
            os.kill(os.getpid(), signal.SIGINT)
        return on_step(self)

    monkeypatch.setattr(mbpo.ModelRollouts, "_on_step", ctrl_c_at_step_250)
    with pytest.raises(KeyboardInterrupt):
        train(cfg, progress=False)
    assert hit
    monkeypatch.undo()
    run = tmp_path / "runs" / "cut"
    saved = sorted((run / "checkpoints").glob("model_*_steps.zip"))
    assert saved and (run / "checkpoints" / f"{saved[-1].stem}_replay_buffer.pkl").is_file()
    _, data, starts = mbpo_state.load_state(run / mbpo_state.STATE_DIR, 1, 0)
    assert len(starts) > 96  # the first episodes' states (none from a planner)
    # 200 updates on the model leave SAC close to random: the planner's rail held the zones where EnergyPlus runs
    railed = [e.value for e in scalars(tmp_path / "tb" / "cut")["mbpo/railed_steps"]]
    episodes = pd.read_csv(run / "episodes.csv")
    assert railed[-1] > 0 and episodes["east_temp_max"].max() < 40, (railed[-1], episodes["east_temp_max"].max())
    with caplog.at_level("INFO"):
        final = train(TrainConfig(timesteps=int(saved[-1].stem.split("_")[1]) + 96), resume=saved[-1],
                      progress=False)  # fmt: skip
    assert "replay buffer restored" in caplog.text and "the ensemble resumes" in caplog.text
    _, data_after, starts_after = mbpo_state.load_state(run / mbpo_state.STATE_DIR, 1, 0)
    assert len(starts_after) > len(starts) and len(data_after) > len(data)
    assert final.is_file()


@pytest.mark.slow
def test_the_multiplier_moves_the_policy_toward_the_band(planner_run, tmp_path, no_leaks):
    """The same pretraining on the planner's model, comfort priced at the multiplier's floor and at its cap: the
    policy that pays for comfort keeps the model's zones nearer the band (the constraint's cost of its rollouts)."""
    costs = {}
    for name, price in (("cheap", 0.1), ("dear", 100.0)):
        mbpo_settings = MBPOSettings(**{**ROLLOUTS.__dict__, "pretrain_updates": 1200, "rollout_every": 400,
                                        "rollout_length": 4})  # fmt: skip
        comfort = ComfortConstraint(target_pct=99.0, multiplier_init=price)
        train(mbpo_config(tmp_path, name, planner_run, timesteps=2, comfort=comfort, mbpo=mbpo_settings),
              progress=False)  # fmt: skip
        first = scalars(tmp_path / "tb" / name)["mbpo/model_cost"][0]  # the pretrained policy's last rollouts
        assert first.step == 0
        costs[name] = first.value
    assert costs["dear"] < 0.8 * costs["cheap"], costs  # measured: 0.42 against 0.69 (1,200 updates)


def test_settings_text_round_trips_and_refusals():
    sac = SACSettings.from_text("ent_coef=0.05,net_arch=128x128,gradient_steps=2", SACSettings(gamma=0.95))
    assert (sac.ent_coef, sac.net_arch, sac.gradient_steps, sac.gamma) == ("0.05", (128, 128), 2, 0.95)
    settings = MBPOSettings.from_text("rollout_length=3,rail_k=none,real_ratio=0.05")
    assert (settings.rollout_length, settings.rail_k, settings.real_ratio) == (3, None, 0.05)
    cfg = TrainConfig(algorithm="mbpo", mbpo=settings, sac=sac, comfort=ComfortConstraint(target_pct=99.6))
    assert TrainConfig.from_json(cfg.to_json()) == cfg  # a run's config.json gives its settings back
    with pytest.raises(ValueError, match="horizon takes a value"):
        MPCSettings.from_text("horizon=none")
    with pytest.raises(ValueError, match="--mbpo 'rollouts=3': expected NAME=VALUE"):
        MBPOSettings.from_text("rollouts=3")
    with pytest.raises(ValueError, match="rollout_length 9"):
        MBPOSettings.from_text("rollout_length=9")
    with pytest.raises(ValueError, match="give --comfort-target"):
        TrainConfig(algorithm="mbpo", weathers=["CA"]).resolved()
    with pytest.raises(ValueError, match="at most --mpc horizon"):
        TrainConfig(algorithm="mbpo", weathers=["CA"], mbpo=MBPOSettings(rollout_length=8),
                    mpc=MPCSettings(horizon=4), comfort=ComfortConstraint(target_pct=99.6)).resolved()  # fmt: skip
