"""The learner's numpy policy computes what SB3's torch policy computes."""

import gymnasium as gym
import numpy as np
import torch as th
from stable_baselines3.common.policies import ActorCriticPolicy

from parallel_eplus.env import action_space, observation_space
from parallel_eplus.rollout import NumpyPolicy
from parallel_eplus.train import TRPOSettings


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
