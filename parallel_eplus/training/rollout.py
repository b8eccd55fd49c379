"""The learner's side of a control step: SB3's rollout loop with the policy evaluated in numpy.

Why: with two workers, SB3's loop cost 0.93 ms of learner CPU per vector step, most of it torch
dispatch for a 32x32 network, a `Normal` per step and tensor conversions, while every EnergyPlus
worker waited for its action; on a 2-core machine that CPU is also taken from EnergyPlus. With the
same arithmetic on numpy arrays the loop costs 0.36 ms. Everything else is SB3's: the rollout
buffer, the timeout bootstrap, the callbacks and the algorithm's update, which still runs in torch.

With local workers the loop is also pipelined: each worker gets its next action as soon as its own
observation arrives, instead of every worker waiting for the slowest at every step (SB3's lockstep
`VecEnv`). Each worker fills its own column of the buffer; callbacks still see whole vector steps.
Each worker draws its exploration noise from a stream of its own, so with fixed observation
statistics both loops collect the same rollout. The price of pipelining: the running statistics are
updated in the order workers are served, which depends on timing, so a seed no longer fixes a
training run bit for bit (`lockstep = True` does).
"""

from __future__ import annotations

import math

import numpy as np
import torch as th
from gymnasium import spaces
from sb3_contrib import TRPO
from stable_baselines3 import PPO, SAC
from stable_baselines3.common.buffers import RolloutBuffer
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.distributions import DiagGaussianDistribution
from stable_baselines3.common.policies import ActorCriticPolicy
from stable_baselines3.common.preprocessing import is_image_space
from stable_baselines3.common.torch_layers import FlattenExtractor, MlpExtractor
from stable_baselines3.common.vec_env import VecEnv, VecNormalize

from parallel_eplus.training.sb3_adapter import SB3VecEnv

_HALF_LOG_2PI = 0.5 * math.log(2 * math.pi)


def _layers(module: th.nn.Module) -> list[tuple[np.ndarray, np.ndarray, bool]] | None:
    """(weight.T, bias, tanh after?) per Linear of a Linear/Tanh stack; None for anything else."""
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


def _run(layers: list[tuple[np.ndarray, np.ndarray, bool]], x: np.ndarray) -> np.ndarray:
    for w, b, tanh in layers:
        x = x @ w + b
        if tanh:
            np.tanh(x, out=x)
    return x


class NumpyPolicy:
    """A snapshot of an SB3 `MlpPolicy` (Box observations, diagonal Gaussian, tanh MLP) in numpy.

    Take a new snapshot after every update; `supports(policy)` says whether a policy has this shape.
    """

    def __init__(self, policy: ActorCriticPolicy):
        self.actor = _layers(policy.mlp_extractor.policy_net) + _layers(policy.action_net)
        self.critic = _layers(policy.mlp_extractor.value_net) + _layers(policy.value_net)
        log_std = policy.log_std.detach().numpy().astype(np.float64)
        self.std = np.exp(log_std)
        self._log_prob_const = -(log_std.sum() + _HALF_LOG_2PI * log_std.size)

    @staticmethod
    def supports(policy: ActorCriticPolicy) -> bool:
        """Exactly SB3's own classes (a subclass may override any step), on the CPU, flat spaces."""
        if type(policy) is not ActorCriticPolicy or policy.device.type != "cpu":
            return False
        obs_space, act_space = policy.observation_space, policy.action_space
        return (
            isinstance(obs_space, spaces.Box)
            and not (policy.normalize_images and is_image_space(obs_space))
            and isinstance(act_space, spaces.Box)
            and len(act_space.shape) == 1
            and type(policy.action_dist) is DiagGaussianDistribution
            and not policy.squash_output
            and not policy.use_sde
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
        return self._log_prob_const - 0.5 * (z * z).sum(axis=1)

    def sample(
        self, obs: np.ndarray, rng: np.random.Generator | list[np.random.Generator]
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Stochastic float32 actions (as the buffer stores them), the critic's values, their log-probabilities.

        `rng`: one generator for every row, or one per row (each worker's own stream).
        """
        x = self._flat(obs)
        mean = _run(self.actor, x)
        if isinstance(rng, np.random.Generator):
            noise = rng.standard_normal(mean.shape)
        else:
            noise = np.array([r.standard_normal(mean.shape[1]) for r in rng])
        actions = (mean + self.std * noise).astype(np.float32)
        return actions, _run(self.critic, x)[:, 0], self.log_prob(actions, mean)


def _pipelinable(env: VecEnv) -> tuple[SB3VecEnv | None, VecNormalize | None]:
    """Our local workers, and the observation normalization over them, when they can be stepped one by one."""
    norm = None
    if isinstance(env, VecNormalize) and not env.norm_reward and not isinstance(env.obs_rms, dict):
        norm, env = env, env.venv
    if isinstance(env, SB3VecEnv) and env.steps_one_by_one and env.num_envs > 1:
        return env, norm
    return None, None


class NumpyRollouts:
    """For SB3's on-policy algorithms: collect rollouts with a `NumpyPolicy` when the policy has its shape.

    Saved models are the algorithm's ordinary models: `sb3_contrib.TRPO.load` (or `PPO.load`) reads them.
    """

    lockstep = False  # True: step every worker together, as SB3 does (a seed then fixes the run bit for bit)

    def set_random_seed(self, seed: int | None = None) -> None:
        super().set_random_seed(seed)  # SB3 calls this while setting the model up, seed or not
        # One stream per worker: its draws then do not depend on the order workers are served in. A
        # resumed run (SB3 restores num_timesteps first) draws afresh rather than replaying its start.
        entropy = None if seed is None else [seed, self.num_timesteps]
        self._rngs = [np.random.default_rng(s) for s in np.random.SeedSequence(entropy).spawn(self.n_envs)]

    def _excluded_save_params(self) -> list[str]:
        return [*super()._excluded_save_params(), "_rngs", "lockstep"]

    def collect_rollouts(
        self, env: VecEnv, callback: BaseCallback, rollout_buffer: RolloutBuffer, n_rollout_steps: int
    ) -> bool:
        if not NumpyPolicy.supports(self.policy):
            return super().collect_rollouts(env, callback, rollout_buffer, n_rollout_steps)
        assert self._last_obs is not None, "No previous observation was provided"
        self.policy.set_training_mode(False)
        policy = NumpyPolicy(self.policy)
        workers, norm = (None, None) if self.lockstep else _pipelinable(env)
        if workers is not None:
            return self._collect_pipelined(policy, workers, norm, callback, rollout_buffer, n_rollout_steps)
        low, high = self.action_space.low, self.action_space.high
        rollout_buffer.reset()
        callback.on_rollout_start()
        for _ in range(n_rollout_steps):
            actions, values, log_probs = policy.sample(self._last_obs, self._rngs)
            clipped_actions = np.clip(actions, low, high)  # the buffer keeps the unclipped ones, as in SB3
            new_obs, rewards, dones, infos = env.step(clipped_actions)
            self.num_timesteps += env.num_envs
            callback.update_locals(locals())
            if not callback.on_step():
                return False
            self._update_info_buffer(infos, dones)
            # A cut (not finished) episode: bootstrap with the value of where it stopped (SB3 issue #633).
            for i in np.flatnonzero(dones):
                terminal = infos[i].get("terminal_observation")
                if terminal is not None and infos[i].get("TimeLimit.truncated", False):
                    rewards[i] += self.gamma * policy.value(terminal[None])[0]
            rollout_buffer.add(
                self._last_obs, actions, rewards, self._last_episode_starts,
                th.from_numpy(values), th.from_numpy(log_probs),
            )  # fmt: skip
            self._last_obs = new_obs
            self._last_episode_starts = dones
        values = th.from_numpy(policy.value(new_obs))
        rollout_buffer.compute_returns_and_advantage(last_values=values, dones=dones)
        callback.update_locals(locals())
        callback.on_rollout_end()
        return True

    def _collect_pipelined(
        self, policy: NumpyPolicy, env: SB3VecEnv, norm: VecNormalize | None, callback: BaseCallback,
        buffer: RolloutBuffer, n_steps: int,
    ) -> bool:  # fmt: skip
        """`collect_rollouts`, serving each worker as soon as its observation arrives.

        Worker i's t-th transition goes to row t, column i of the buffer, as in the lockstep loop. Once
        every worker has made step t, the callbacks see that vector step whole. Of `VecNormalize.step_wait`
        this does what a run with `norm_reward=False` uses: the observation statistics, not the returns'.
        """
        assert n_steps == buffer.buffer_size
        finished = False
        try:
            finished = self._pipeline(policy, env, norm, callback, buffer, n_steps)
            return finished
        finally:
            if not finished:  # stopped or failed with workers mid-step: the next `learn` must start
                self._last_obs = None  # them afresh, which SB3 does when there is no last observation

    def _pipeline(
        self, policy: NumpyPolicy, env: SB3VecEnv, norm: VecNormalize | None, callback: BaseCallback,
        buffer: RolloutBuffer, n_steps: int,
    ) -> bool:  # fmt: skip
        n = env.num_envs
        low, high = self.action_space.low, self.action_space.high
        obs = np.array(self._last_obs)  # normalized, as the policy sees it
        raw = np.array(norm.old_obs if norm is not None else obs)
        starts = np.array(self._last_episode_starts, dtype=bool)  # worker i's last `done`
        step = [0] * n
        step_infos: list[list[dict]] = [[{} for _ in range(n)] for _ in range(n_steps)]
        step_dones = np.zeros((n_steps, n), dtype=bool)
        buffer.reset()
        callback.on_rollout_start()

        def act(i: int) -> None:
            t = step[i]
            actions, values, log_probs = policy.sample(obs[i : i + 1], self._rngs[i : i + 1])
            buffer.observations[t, i] = obs[i]
            buffer.actions[t, i] = actions[0]
            buffer.episode_starts[t, i] = starts[i]
            buffer.values[t, i] = values[0]
            buffer.log_probs[t, i] = log_probs[0]
            env.send_one(i, np.clip(actions[0], low, high))  # the buffer keeps the unclipped one, as in SB3

        for i in range(n):
            act(i)
        pending, reported = set(range(n)), 0
        while pending:
            for i in env.ready(pending):
                answer = env.receive_one(i)
                if answer is None:  # its next episode is starting up: served when it is ready
                    continue
                new_obs, reward, done, info = answer
                raw[i] = new_obs
                if norm is not None and norm.norm_obs:
                    # `VecNormalize.step_wait` on one row, minus the fixed costs that made it the learner's
                    # largest per-step item: a row's mean is itself and its variance 0 (what `update`
                    # would reduce to, bit for bit), and `normalize_obs` would deep-copy the row first.
                    if norm.training:
                        norm.obs_rms.update_from_moments(new_obs, 0.0, 1)
                    new_obs = norm._normalize_obs(new_obs, norm.obs_rms).astype(np.float32)
                    if done and "terminal_observation" in info:
                        info["terminal_observation"] = norm.normalize_obs(info["terminal_observation"])
                if done and info.get("TimeLimit.truncated", False) and "terminal_observation" in info:
                    reward += self.gamma * policy.value(info["terminal_observation"][None])[0]  # SB3 issue #633
                t = step[i]
                buffer.rewards[t, i] = reward
                step_infos[t][i], step_dones[t, i] = info, done
                obs[i], starts[i] = new_obs, done
                step[i] = t + 1
                if step[i] < n_steps:
                    act(i)
                else:
                    pending.discard(i)
            while reported < min(step):  # vector steps every worker has made, for the callbacks
                self.num_timesteps += n
                infos, dones = step_infos[reported], step_dones[reported]
                callback.update_locals({"infos": infos, "dones": dones})
                if not callback.on_step():
                    return False
                self._update_info_buffer(infos, dones)
                step_infos[reported] = []
                reported += 1
        buffer.pos, buffer.full = n_steps, True
        self._last_obs, self._last_episode_starts = obs, starts
        if norm is not None:
            norm.old_obs = raw
        values = th.from_numpy(policy.value(obs))
        buffer.compute_returns_and_advantage(last_values=values, dones=starts)
        callback.update_locals({"new_obs": obs, "dones": starts, "values": values})
        callback.on_rollout_end()
        return True


class FastTRPO(NumpyRollouts, TRPO):
    """sb3-contrib's TRPO (the paper's algorithm) with the numpy rollout loop."""


class FastPPO(NumpyRollouts, PPO):
    """Stable-Baselines3's PPO with the numpy rollout loop: the comparison the paper did not run."""


# SAC is off-policy: SB3's own step-by-step collect_rollouts feeds its replay buffer.
ALGORITHMS: dict[str, type] = {"trpo": FastTRPO, "ppo": FastPPO, "sac": SAC}
