"""The policy as the rollout loop uses it: an SB3 `MlpPolicy` snapshot evaluated in numpy.

Why: with two workers, SB3's loop cost 0.93 ms of learner CPU per vector step, most of it torch
dispatch for a 32x32 network, a `Normal` per step and tensor conversions, while every EnergyPlus
worker waited for its action. The same arithmetic on numpy arrays costs 0.36 ms. A snapshot is a few
kB of plain arrays, so it also travels: a Ray actor receives one per batch and acts on its node, where this module
imports neither torch nor SB3 (they are imported where a snapshot is taken, in the learner).
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np

from parallel_eplus.buildings.scaling import denormalize

if TYPE_CHECKING:
    import torch as th
    from stable_baselines3.common.policies import ActorCriticPolicy

_HALF_LOG_2PI = 0.5 * math.log(2 * math.pi)


def _layers(module: th.nn.Module) -> list[tuple[np.ndarray, np.ndarray, bool]] | None:
    """(weight.T, bias, tanh after?) per Linear of a Linear/Tanh stack; None for anything else."""
    import torch as th

    layers: list[tuple[np.ndarray, np.ndarray, bool]] = []
    for m in module.modules() if isinstance(module, th.nn.Sequential) else [module]:
        if isinstance(m, th.nn.Sequential):
            continue
        if type(m) is th.nn.Linear and m.bias is not None:
            layers.append((m.weight.detach().numpy().T.copy(), m.bias.detach().numpy().copy(), False))
        elif type(m) is th.nn.Tanh and layers and not layers[-1][2]:
            layers[-1] = (*layers[-1][:2], True)
        else:
            return None
    return layers


def _fuse(actor: list, critic: list) -> list[tuple[np.ndarray, np.ndarray, bool]] | None:
    """One stack computing [actor | critic] side by side (the first layer's weights joined, the others block-diagonal),
    so a step costs one matmul per layer instead of two: numpy's fixed cost per call, not the arithmetic, is the
    price of a 32x32 network on one row. None where the two stacks differ in shape."""
    if len(actor) != len(critic) or any(a[2] != c[2] for a, c in zip(actor, critic, strict=True)):
        return None
    fused = [(np.hstack([actor[0][0], critic[0][0]]), np.concatenate([actor[0][1], critic[0][1]]), actor[0][2])]
    for (wa, ba, tanh), (wc, bc, _) in zip(actor[1:], critic[1:], strict=True):
        w = np.zeros((wa.shape[0] + wc.shape[0], wa.shape[1] + wc.shape[1]))
        w[: wa.shape[0], : wa.shape[1]], w[wa.shape[0] :, wa.shape[1] :] = wa, wc
        fused.append((w, np.concatenate([ba, bc]), tanh))
    return fused


def _run(layers: list[tuple[np.ndarray, np.ndarray, bool]], x: np.ndarray) -> np.ndarray:
    for w, b, tanh in layers:
        x = x @ w + b
        if tanh:
            np.tanh(x, out=x)
    return x


class NumpyPolicy:
    """A snapshot of an SB3 `MlpPolicy` (Box observations, diagonal Gaussian, tanh MLP) in numpy.

    Take a new snapshot after every update; `supports(policy)` says whether a policy has this shape.
    With gSDE (`use_sde`, Raffin et al. 2022) the exploration noise is the policy's last hidden layer times a
    matrix drawn per worker and kept for `sde_sample_freq` of its steps (the whole batch if <= 0), as SB3 does:
    an offset that persists long enough for a building to respond to it.
    """

    def __init__(self, policy: ActorCriticPolicy, sde_sample_freq: int = -1):
        self.latent = _layers(policy.mlp_extractor.policy_net)
        self.head = _layers(policy.action_net)
        self.actor = self.latent + self.head
        self.critic = _layers(policy.mlp_extractor.value_net) + _layers(policy.value_net)
        self.both = _fuse(self.actor, self.critic)  # the rollout's per-step forward pass: mean and value at once
        self.n_actions = self.actor[-1][0].shape[1]
        log_std = policy.log_std.detach().numpy().astype(np.float64)
        self.std = np.exp(log_std)
        self.sde = bool(policy.use_sde)
        self.sde_sample_freq = sde_sample_freq
        self._matrices: dict[int, list] = {}  # a worker's generator -> [exploration matrix, steps drawn with it]
        self._log_prob_const = -(log_std.sum() + _HALF_LOG_2PI * log_std.size)

    @staticmethod
    def supports(policy: ActorCriticPolicy) -> bool:
        """Exactly SB3's own classes (a subclass may override any step), on the CPU, flat spaces."""
        from gymnasium import spaces
        from stable_baselines3.common.distributions import DiagGaussianDistribution, StateDependentNoiseDistribution
        from stable_baselines3.common.policies import ActorCriticPolicy
        from stable_baselines3.common.preprocessing import is_image_space
        from stable_baselines3.common.torch_layers import FlattenExtractor, MlpExtractor

        if type(policy) is not ActorCriticPolicy or policy.device.type != "cpu":
            return False
        obs_space, act_space = policy.observation_space, policy.action_space
        return (
            isinstance(obs_space, spaces.Box)
            and not (policy.normalize_images and is_image_space(obs_space))
            and isinstance(act_space, spaces.Box)
            and len(act_space.shape) == 1
            and (
                type(policy.action_dist) is DiagGaussianDistribution
                or (
                    type(policy.action_dist) is StateDependentNoiseDistribution
                    and policy.action_dist.full_std
                    and not policy.action_dist.use_expln
                    and policy.action_dist.bijector is None
                )
            )
            and not policy.squash_output
            and type(policy.mlp_extractor) is MlpExtractor
            and type(policy.pi_features_extractor) is FlattenExtractor
            and type(policy.vf_features_extractor) is FlattenExtractor
            and all(
                _layers(m) is not None
                for m in (
                    policy.mlp_extractor.policy_net,
                    policy.mlp_extractor.value_net,
                    policy.action_net,
                    policy.value_net,
                )
            )
        )

    @staticmethod
    def _flat(obs: np.ndarray) -> np.ndarray:
        return obs.reshape(len(obs), -1).astype(np.float64)

    def mean(self, obs: np.ndarray) -> np.ndarray:
        return _run(self.actor, self._flat(obs))

    def value(self, obs: np.ndarray) -> np.ndarray:
        return _run(self.critic, self._flat(obs))[:, 0]

    def log_prob(self, actions: np.ndarray, mean: np.ndarray) -> np.ndarray:
        z = (actions - mean) / self.std
        return self._log_prob_const - 0.5 * np.einsum("ij,ij->i", z, z)

    def sample(
        self, obs: np.ndarray, rng: np.random.Generator | list[np.random.Generator]
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Stochastic float32 actions (as the buffer stores them), the critic's values, their log-probabilities.

        `rng`: one generator for every row, or one per row (each worker's own stream).
        """
        x = self._flat(obs)
        if self.sde:
            return self._sample_sde(x, [rng] * len(x) if isinstance(rng, np.random.Generator) else rng)
        if self.both is not None:
            out = _run(self.both, x)
            mean, values = out[:, : self.n_actions], out[:, self.n_actions]
        else:
            mean, values = _run(self.actor, x), _run(self.critic, x)[:, 0]
        if isinstance(rng, np.random.Generator):
            noise = rng.standard_normal(mean.shape)
        elif len(rng) == 1:  # the pipelined loop's one row: the same draws, without building a list
            noise = rng[0].standard_normal(mean.shape)
        else:
            noise = np.array([r.standard_normal(mean.shape[1]) for r in rng])
        actions = (mean + self.std * noise).astype(np.float32)
        return actions, values, self.log_prob(actions, mean)

    def _sample_sde(self, x: np.ndarray, rngs: list[np.random.Generator]):
        """gSDE's sample: noise = latent @ the worker's matrix; log-probability under N(mean, latent² @ std²)."""
        latent = _run(self.latent, x)
        mean = _run(self.head, latent)
        noise = np.empty_like(mean)
        for i, r in enumerate(rngs):
            held = self._matrices.setdefault(id(r), [None, 0])
            if held[0] is None or (self.sde_sample_freq > 0 and held[1] % self.sde_sample_freq == 0):
                held[0] = r.standard_normal(self.std.shape) * self.std
            held[1] += 1
            noise[i] = latent[i] @ held[0]
        actions = (mean + noise).astype(np.float32)
        var = (latent * latent) @ (self.std * self.std) + 1e-6  # SB3's epsilon
        z2 = (actions - mean) ** 2 / var
        log_prob = -0.5 * (z2 + np.log(var)).sum(axis=1) - _HALF_LOG_2PI * mean.shape[1]
        return actions, _run(self.critic, x)[:, 0], log_prob


def squashed_mean(policy):
    """SAC's deterministic action (tanh of its actor's mean, mapped onto the action space as SB3's `predict` does) in
    numpy float64, as the on-policy mean above: the same arithmetic an exported controller runs (export/graph.py),
    so both give the same setpoints. None for anything but a plain MLP actor (torch then acts)."""
    import torch as th
    from stable_baselines3.common.torch_layers import FlattenExtractor
    from stable_baselines3.sac.policies import SACPolicy

    if (
        type(policy) is not SACPolicy
        or policy.actor.use_sde
        or type(policy.actor.features_extractor) is not FlattenExtractor
    ):
        return None
    steps: list[tuple] = []
    for m in [*policy.actor.latent_pi, policy.actor.mu]:
        if type(m) is th.nn.Linear and m.bias is not None:
            steps.append((m.weight.detach().double().numpy().T.copy(), m.bias.detach().double().numpy().copy()))
        elif type(m) is th.nn.ReLU:
            steps.append((lambda x: np.maximum(x, 0.0),))
        elif type(m) is th.nn.Tanh:
            steps.append((np.tanh,))
        else:
            return None
    low, high = (np.asarray(b, dtype=np.float64) for b in (policy.action_space.low, policy.action_space.high))

    def mean(obs: np.ndarray) -> np.ndarray:
        x = obs.reshape(len(obs), -1).astype(np.float64)
        for step in steps:
            x = x @ step[0] + step[1] if len(step) == 2 else step[0](x)
        return denormalize(np.tanh(x), low, high)  # SB3's squashed action, unscaled

    return mean
