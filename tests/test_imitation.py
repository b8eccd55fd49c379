"""`--init-from-baseline`: the building's own controls recorded, read back and cloned (real EnergyPlus runs)."""

from __future__ import annotations

import json
from pathlib import Path

import gymnasium as gym
import numpy as np
import pandas as pd
import pytest
import torch as th

from parallel_eplus.buildings import resources
from parallel_eplus.buildings.building import load_building
from parallel_eplus.buildings.check.names import check_spec
from parallel_eplus.buildings.spec.load import load_spec
from parallel_eplus.learning.imitation import clone, readbacks, record_baseline
from parallel_eplus.runs.policy_files import load_policy
from parallel_eplus.training.config import ComfortConstraint, ImitationSettings
from parallel_eplus.training.train import train

from .test_train import small_config

CRAC = resources.spec_dir() / "datacenter-crac.toml"


def test_read_backs_are_inferred_from_the_actuators_or_named():
    assert readbacks(None) == [
        ("System Node Setpoint Temperature", "West Zone DEC Outlet Node"),
        ("System Node Setpoint Temperature", "East Zone DEC Outlet Node"),
        ("Fan Air Mass Flow Rate", "West Zone Supply Fan"),
        ("Fan Air Mass Flow Rate", "East Zone Supply Fan"),
    ]
    assert readbacks("office-small")[0] == ("Zone Thermostat Cooling Setpoint Temperature", "Core_ZN")


def _crac_with(tmp_path: Path, action_extra: str, component: str | None = None) -> Path:
    """The CRAC's spec outside the package (models by absolute path), its first action changed."""
    text = CRAC.read_text()
    for key in ("idf", "baseline_idf"):
        name = text.split(f'\n{key} = "', 1)[1].split('"', 1)[0]
        text = text.replace(f'{key} = "{name}"', f'{key} = "{resources.model_file(name)}"', 1)
    text = text.replace('name = "supply_temp_c"', f'name = "supply_temp_c"\n{action_extra}', 1)
    if component:
        text = text.replace('component = "System Node Setpoint", control = "Temperature Setpoint"', component, 1)
    path = tmp_path / "crac.toml"
    path.write_text(text)
    return path


@pytest.mark.slow
def test_a_named_read_back_is_checked_and_an_unknown_one_is_a_note(tmp_path):
    typo = 'readback = { variable = "System Node Setpoint Temperature", key = "Supply Outlet Nod" }'
    bad = _crac_with(tmp_path, typo)
    result = check_spec(load_spec(bad), use_cache=False)
    assert not result.ok and any("actions[0].readback" in p and "Supply Outlet Node" in p for p in result.problems)
    unknown = _crac_with(tmp_path, "", 'component = "System Node Setpoint", control = "Temperature Maximum Setpoint"')
    result = check_spec(load_spec(unknown), use_cache=False)
    assert result.ok and any("actions[0].readback: none known" in n for n in result.notes)
    with pytest.raises(ValueError, match=r"readback = \{ variable"):
        readbacks(str(unknown))


@pytest.mark.slow
def test_the_cloned_policy_tracks_what_the_built_in_controls_chose(tmp_path, no_leaks):
    """Two January days of the data center's own controls on two weathers; the policy fitted to them chooses
    close to what they chose, and far closer than before fitting."""
    from stable_baselines3.common.vec_env import DummyVecEnv, VecNormalize

    from parallel_eplus.envs.env import action_space, observation_space
    from parallel_eplus.learning.algorithms import ALGORITHMS

    demos = record_baseline(None, ["CA", "FL"], 2, 2, tmp_path / "record", progress=False)
    assert len(demos) == 2 * 2 * 96 and demos.observations.shape[1] == 6
    assert set(demos.weathers) == {"CA", "FL"}
    # what the controls chose, read back: setpoints in their range, fans near the top of theirs
    assert demos.physical[:, :2].min() >= 10 and demos.physical[:, :2].max() <= 20
    assert demos.physical[:, 2:].min() > 4.0

    class Shape(gym.Env):  # the spaces SB3 builds the policy from; never stepped
        def __init__(self):
            self.observation_space, self.action_space = observation_space(), action_space(4)

    env = VecNormalize(DummyVecEnv([Shape]), norm_reward=False)
    model = ALGORITHMS["trpo"]("MlpPolicy", env, n_steps=64, seed=0, device="cpu",
                               policy_kwargs={"net_arch": [32, 32], "activation_fn": th.nn.Tanh})  # fmt: skip

    def error(m) -> np.ndarray:
        with th.no_grad():
            obs = th.as_tensor(env.normalize_obs(demos.observations), dtype=th.float32)
            mean = m.policy.action_net(m.policy.mlp_extractor.forward_actor(m.policy.extract_features(obs)))
        return np.abs(demos.to_physical(mean.numpy()) - demos.to_physical(demos.actions)).mean(axis=0)

    env.obs_rms.mean, env.obs_rms.var = demos.observations.mean(0), demos.observations.var(0)
    before = error(model)
    report = clone(model, env, demos, ImitationSettings(epochs=60), regulated=[1, 2], band=(22.0, 25.0))
    after = error(model)
    assert (after < before / 3).all(), (before, after)
    assert after[0] < 1.0 and after[2] < 0.3  # °C, kg/s: mean absolute error over the recorded steps
    assert report["samples"] == len(demos) and set(report["rmse"]) == set(demos.names)
    assert np.allclose(model.policy.log_std.detach().numpy(), ImitationSettings().log_std)
    # The zones the controls hold barely move in the record; re-drawn in the fit, they barely move the clone.
    shifted = demos.observations.copy()
    shifted[:, 1:3] -= 3.0
    with th.no_grad():

        def chosen(o):
            x = th.as_tensor(env.normalize_obs(o), dtype=th.float32)
            return demos.to_physical(model.policy.action_net(model.policy.mlp_extractor.forward_actor(x)).numpy())

        moved = np.abs(chosen(shifted) - chosen(demos.observations)).mean(axis=0)
    assert moved[0] < 1.0, moved  # °C of setpoint for 3 K of zone temperature


@pytest.mark.slow
def test_train_init_from_baseline_saves_the_cloned_policy_first(tmp_path, no_leaks):
    cfg = small_config(tmp_path, "bc", init_from_baseline=True, timesteps=768)
    train(cfg, progress=False)
    run = tmp_path / "runs" / "bc"
    report = json.loads((run / "imitation.json").read_text())
    assert report["samples"] == 3 * 2 * 96 and report["weathers"] == ["CA", "CO", "FL"]
    act = load_policy(run / "cloned" / "model.zip")  # evaluable on its own: how close before any RL
    obs = np.array([[12.0, 23.0, 24.0, 120e3, 110e3, 10e3]], dtype=np.float32)
    assert act(obs).shape == (1, 4)
    assert not (run / "baseline-record").exists()  # the recorded years' CSVs are not kept


@pytest.mark.slow
def test_sac_from_the_clone_acts_its_warm_up_with_the_cloned_actor_not_random_actions(tmp_path, no_leaks):
    """SAC fills its replay buffer before its first update (`learning_starts`); after `--init-from-baseline` those
    steps are the cloned actor's (its log-std head flat at the clone's spread), so the warm-up episodes stay near the
    built-in controls' comfort and HVAC energy: uniform random setpoints held the office in its bounds 79 % of the
    time at twice the HVAC energy."""
    cfg = small_config(
        tmp_path,
        "sac-clone",
        building="office-small",
        algorithm="sac",
        init_from_baseline=True,
        comfort=ComfortConstraint(target_pct=97.5),
        weathers=["CA"],
        workers=1,
        timesteps=576,
    )
    model = train(cfg, progress=False)
    run = tmp_path / "runs" / "sac-clone"
    assert json.loads((run / "config.json").read_text())["sac"]["learning_starts"] > 576  # all of it warm-up
    own = pd.read_csv(run / "builtin.csv").iloc[0]
    warm = [json.loads(p.read_text()) for p in sorted(run.glob("episodes/worker-0/episode-*/summary.json"))]
    warm = [w for w in warm if w.get("complete", True) and w["steps"] == own["steps"]]
    assert warm, "the warm-up's whole episodes"
    for episode in warm:
        assert episode["in_band_pct"] >= 90.0, episode["in_band_pct"]
        assert episode["hvac_energy_kwh"] <= 1.25 * own["hvac_energy_kwh"], (episode["hvac_energy_kwh"], own)
    assert model.is_file()


@pytest.mark.slow
def test_the_medium_office_s_own_controls_are_read_back_at_every_step_among_its_own_detailed_outputs(
    tmp_path, no_leaks
):
    """The DOE medium office reports some of its own outputs at the HVAC's `Detailed` frequency, which adds rows to
    eplusout.csv between the steps: the read-backs are the steps', one per observation, the thermostats on their
    schedules and the supply air on its manager's setpoint."""
    office = load_building("office-medium")
    demos = record_baseline("office-medium", ["CA"], 1, 1, tmp_path / "record", progress=False)
    assert len(demos) == office.steps_per_day and not np.isnan(demos.physical).any()
    names = [a.name for a in office.actions]
    heating = demos.physical[:, names.index("heating_setpoint_c")]
    supply = demos.physical[:, names.index("supply_air_c")]
    assert set(np.round(heating, 1)) <= {15.6, 21.0} and 10.0 <= supply.min() <= supply.max() <= 16.0
