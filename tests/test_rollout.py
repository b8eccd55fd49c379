"""The learner's numpy policy computes what SB3's torch policy computes, and its pipelined loop
collects what SB3's lockstep loop collects."""

import gymnasium as gym
import numpy as np
import pytest
import torch as th
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.logger import Logger
from stable_baselines3.common.policies import ActorCriticPolicy
from stable_baselines3.common.vec_env import VecNormalize

from parallel_eplus.buildings.datacenter import STEPS_PER_DAY
from parallel_eplus.engine.config import SimulationConfig
from parallel_eplus.envs.env import action_space, observation_space
from parallel_eplus.envs.vector_env import EnergyPlusVectorEnv
from parallel_eplus.learning.algorithms import FastTRPO
from parallel_eplus.learning.rollout import _pipelinable
from parallel_eplus.learning.sb3_adapter import SB3VecEnv
from parallel_eplus.runs.numpy_policy import NumpyPolicy
from parallel_eplus.training.config import TRPOSettings


def _policy(time_features: bool) -> ActorCriticPolicy:
    th.manual_seed(1)
    policy = ActorCriticPolicy(
        observation_space(time_features), action_space(4), lambda _: 1e-3,
        net_arch=list(TRPOSettings().net_arch), activation_fn=th.nn.Tanh,
    )  # fmt: skip
    with th.no_grad():  # a trained policy's exploration noise differs per action
        policy.log_std.copy_(th.tensor([-0.3, 0.1, -1.2, 0.4]))
    return policy


def test_numpy_policy_matches_torch():
    for time_features in (False, True):
        policy = _policy(time_features)
        assert NumpyPolicy.supports(policy)
        fast = NumpyPolicy(policy)
        obs = np.random.default_rng(0).normal(size=(5, policy.observation_space.shape[0])).astype(np.float32)
        with th.no_grad():
            dist = policy.get_distribution(th.as_tensor(obs))
            mean = dist.distribution.mean.numpy()
            actions = dist.sample()
            log_prob = dist.log_prob(actions).numpy()
            value = policy.predict_values(th.as_tensor(obs)).numpy()[:, 0]
        np.testing.assert_allclose(fast.mean(obs), mean, rtol=1e-5, atol=1e-6)
        np.testing.assert_allclose(fast.value(obs), value, rtol=1e-5, atol=1e-6)
        np.testing.assert_allclose(fast.log_prob(actions.numpy(), fast.mean(obs)), log_prob, rtol=1e-5, atol=1e-5)


def test_numpy_gsde_samples_as_sb3_scores_them_and_holds_its_noise():
    """gSDE: the numpy sample's log-probability is SB3's `evaluate_actions` (what the update uses); each worker's
    noise matrix is held `sde_sample_freq` of its steps, then drawn anew."""
    from stable_baselines3.common.policies import ActorCriticPolicy

    from parallel_eplus.envs.env import action_space, observation_space

    policy = ActorCriticPolicy(observation_space(), action_space(4), lambda _: 3e-4, net_arch=[32, 32],
                               activation_fn=th.nn.Tanh, use_sde=True, log_std_init=-1.0)  # fmt: skip
    assert NumpyPolicy.supports(policy)
    fast = NumpyPolicy(policy, sde_sample_freq=2)
    obs = np.random.default_rng(0).normal(size=(3, 6)).astype(np.float32)
    rngs = [np.random.default_rng(i) for i in range(3)]
    actions, values, log_prob = fast.sample(obs, rngs)
    with th.no_grad():
        _, expected, _ = policy.evaluate_actions(th.as_tensor(obs), th.as_tensor(actions))
    np.testing.assert_allclose(log_prob, expected.numpy(), rtol=1e-5, atol=1e-5)
    held, _, _ = fast.sample(obs[:1], rngs[:1])  # worker 0's second step: the same matrix, the same action
    np.testing.assert_array_equal(held[0], actions[0])
    fresh, _, _ = fast.sample(obs[:1], rngs[:1])  # its third: a new matrix
    assert not np.array_equal(fresh[0], actions[0])


def test_numpy_policy_samples_with_the_policys_spread():
    policy = _policy(False)
    fast = NumpyPolicy(policy)
    obs = np.zeros((20000, 6), dtype=np.float32)
    actions, values, log_probs = fast.sample(obs, np.random.default_rng(0))
    np.testing.assert_allclose(actions.std(axis=0), policy.log_std.exp().detach().numpy(), rtol=0.03)
    assert values.shape == log_probs.shape == (20000,)


def test_other_policy_shapes_fall_back_to_sb3():
    def policy(obs=None, act=None, **kwargs):
        obs, act = obs or observation_space(False), act or action_space(4)
        return ActorCriticPolicy(obs, act, lambda _: 1e-3, **{"activation_fn": th.nn.Tanh, **kwargs})

    assert NumpyPolicy.supports(policy())
    assert not NumpyPolicy.supports(policy(activation_fn=th.nn.ReLU))
    assert not NumpyPolicy.supports(policy(act=gym.spaces.Box(-1, 1, (2, 3), np.float32)))  # not flat
    image = gym.spaces.Box(0, 255, (3, 36, 36), np.uint8)  # SB3 scales images by 1/255 first
    assert not NumpyPolicy.supports(policy(obs=image))


def _one_rollout(out_dir, lockstep: bool, backend: str = "local", stats: list | None = None) -> dict[str, np.ndarray]:
    """One TRPO rollout (2 workers, CA and CO, 128 steps each: a day's episode ends inside it).

    backend "ray": the same two workers in two Ray actors of one worker each, collecting fragments."""
    sim = SimulationConfig(run_days=1, output_dir=str(out_dir), keep_episodes=0)
    if backend == "ray":
        from parallel_eplus.learning.ray_vector_env import RayVectorEnv

        venv = RayVectorEnv(sim, [["CA"], ["CO"]], workers_per_actor=1)
    else:
        venv = EnergyPlusVectorEnv(sim, [["CA"], ["CO"]])
    env = VecNormalize(SB3VecEnv(venv), norm_reward=False)
    env.training = False  # fixed statistics: served in any order, each worker sees the same numbers
    try:
        model = FastTRPO(
            "MlpPolicy", env, n_steps=128, batch_size=128, seed=3, device="cpu",
            policy_kwargs={"net_arch": [32, 32], "activation_fn": th.nn.Tanh},
        )  # fmt: skip
        model.lockstep = lockstep
        model.set_logger(Logger(None, []))  # no SB3-<time> folder in the temp folder
        assert (_pipelinable(env)[0] is not None) and model.n_envs == 2
        model.learn(256)  # one rollout, then one update (which leaves the buffer's contents alone)
        if stats is not None:
            stats.extend(venv.stats)
        if backend == "ray":  # the actors step through SB3's episode keys without SB3 (test_packaging: no torch)
            import ray

            kind = lambda actor: type(actor.env).__name__  # noqa: E731
            assert ray.get([a.__ray_call__.remote(kind) for a in venv.actors]) == ["EpisodeKeys", "EpisodeKeys"]
        b = model.rollout_buffer
        return {k: getattr(b, k).copy() for k in ("observations", "actions", "rewards", "episode_starts", "values",
                                                  "log_probs", "returns")}  # fmt: skip
    finally:
        env.close()


def test_one_row_statistics_update_is_vecnormalizes_own_bit_for_bit():
    """The pipelined loop updates and applies the observation statistics one row at a time, cheaply."""
    from stable_baselines3.common.running_mean_std import RunningMeanStd

    rows = np.random.default_rng(0).normal(20.0, 5.0, size=(300, 6)).astype(np.float32)
    ours, sb3 = RunningMeanStd(shape=(6,)), RunningMeanStd(shape=(6,))
    for row in rows:
        ours.update_from_moments(row, 0.0, 1)  # as rollout.py does
        sb3.update(row[None])  # as VecNormalize.step_wait does
    np.testing.assert_array_equal(ours.mean, sb3.mean)
    np.testing.assert_array_equal(ours.var, sb3.var)
    assert ours.count == sb3.count


@pytest.mark.slow
def test_pipelined_rollout_collects_what_the_lockstep_one_does(tmp_path, no_leaks, monkeypatch):
    """Serving each worker as its observation arrives fills the same buffer: every column is its worker's."""
    served: list[int] = []
    receive_one = SB3VecEnv.receive_one
    monkeypatch.setattr(SB3VecEnv, "receive_one", lambda self, i: served.append(i) or receive_one(self, i))
    lockstep = _one_rollout(tmp_path / "lockstep", lockstep=True)
    assert served == []
    pipelined = _one_rollout(tmp_path / "pipelined", lockstep=False)
    assert sorted(served) == [0] * 129 + [1] * 129  # each step, and the new day's first observation
    for key, value in lockstep.items():
        np.testing.assert_allclose(pipelined[key], value, rtol=1e-5, atol=1e-6, err_msg=key)
    starts = lockstep["episode_starts"]  # (step, worker): both days ended and restarted inside the rollout
    assert starts.shape == (128, 2) and starts[0].all() and starts[STEPS_PER_DAY].all() and starts.sum() == 4
    # The update flattened the rest worker by worker: 128 steps of CA, then 128 of CO.
    obs = lockstep["observations"]
    assert obs.shape == (256, 6) and not np.allclose(obs[:128], obs[128:])


@pytest.mark.slow
def test_ray_actors_collect_the_batch_local_workers_collect(tmp_path, no_leaks):
    """Fragments from Ray actors (one call per actor per batch) fill the buffer the local loop fills."""
    pytest.importorskip("ray")
    local = _one_rollout(tmp_path / "local", lockstep=False)
    stats: list = []
    ray = _one_rollout(tmp_path / "ray", lockstep=False, backend="ray", stats=stats)
    for key, value in local.items():  # observations, actions, rewards, starts, values, log-probs, returns
        np.testing.assert_allclose(ray[key], value, rtol=1e-5, atol=1e-6, err_msg=key)
    assert ray["episode_starts"].sum() == 4  # both days ended inside the fragments and restarted
    assert [s.round_trips for s in stats] == [2] and stats[0].progress_checks == 0


class _StopAfter(BaseCallback):
    def __init__(self, calls: int):
        super().__init__()
        self.calls = calls

    def _on_step(self) -> bool:
        return self.n_calls < self.calls


@pytest.mark.slow
def test_a_rollout_stopped_midway_starts_the_workers_afresh_at_the_next_learn(tmp_path, no_leaks):
    """Stopped by a callback, pipelined workers are mid-step; the next `learn` must not answer stale actions."""
    sim = SimulationConfig(run_days=1, output_dir=str(tmp_path), keep_episodes=0)
    env = VecNormalize(SB3VecEnv(EnergyPlusVectorEnv(sim, [["CA"], ["CO"]])), norm_reward=False)
    try:
        model = FastTRPO("MlpPolicy", env, n_steps=64, batch_size=64, seed=0, device="cpu")
        model.set_logger(Logger(None, []))
        model.learn(128, callback=_StopAfter(10))
        assert model.num_timesteps == 20 and model._last_obs is None
        model.learn(128, reset_num_timesteps=False)
        starts = model.rollout_buffer.episode_starts
        assert starts[0].all() and not starts[1:].any()  # a fresh episode on each worker, then no reset
        assert model.num_timesteps == 20 + 128
    finally:
        env.close()
