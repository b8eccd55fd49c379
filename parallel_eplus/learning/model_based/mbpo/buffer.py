"""`--algorithm mbpo`'s replay buffer: SB3's, with the comfort costs of the real steps (lagrangian.py's
`CostReplayBuffer`) and the ensemble's transitions beside them (mbpo.py adds those), sampled together."""

from __future__ import annotations

import numpy as np
import torch as th
from stable_baselines3.common.type_aliases import ReplayBufferSamples

from parallel_eplus.learning.lagrangian import CostReplayBuffer


class ModelMixBuffer(CostReplayBuffer):
    """The real transitions (SB3's replay buffer, with their comfort costs) and the model's, sampled together."""

    real_ratio: float = 0.1

    def __init__(self, *args, model_size: int = 100_000, **kwargs):
        super().__init__(*args, **kwargs)
        self.model_size, self.model_pos, self.model_full = model_size, 0, False
        n_obs, n_act = self.obs_shape[0], self.action_dim
        self.m_obs = np.zeros((model_size, n_obs), np.float32)
        self.m_next = np.zeros((model_size, n_obs), np.float32)
        self.m_act = np.zeros((model_size, n_act), np.float32)
        self.m_reward = np.zeros(model_size, np.float32)
        self.m_cost = np.zeros(model_size, np.float32)

    def model_rows(self) -> int:
        return self.model_size if self.model_full else self.model_pos

    def add_model(self, obs, action, reward, cost, next_obs) -> None:
        """Model transitions (raw observations, as the real ones are kept); the oldest are overwritten."""
        for i in range(len(obs)):
            j = self.model_pos
            self.m_obs[j], self.m_act[j], self.m_next[j] = obs[i], action[i], next_obs[i]
            self.m_reward[j], self.m_cost[j] = reward[i], cost[i]
            self.model_pos = (j + 1) % self.model_size
            self.model_full |= self.model_pos == 0

    def sample(self, batch_size: int, env=None) -> ReplayBufferSamples:
        rows = self.model_rows()
        n_model = 0 if rows == 0 else int(round(batch_size * (1 - self.real_ratio)))
        if self.size() == 0:  # nothing real yet (a run started from a planner's data): the model's alone
            n_model = batch_size
        parts = [super().sample(batch_size - n_model, env)] if n_model < batch_size else []
        if n_model:
            idx = np.random.randint(0, rows, size=n_model)
            rewards = self.m_reward[idx] - self.multiplier * self.m_cost[idx]
            data = (
                self._normalize_obs(self.m_obs[idx], env), self.m_act[idx], self._normalize_obs(self.m_next[idx], env),
                np.zeros((n_model, 1), np.float32), self._normalize_reward(rewards.reshape(-1, 1), env),
            )  # fmt: skip
            parts.append(ReplayBufferSamples(*tuple(map(self.to_torch, data))))
        joined = [None if t[0] is None else th.cat(t) for t in zip(*parts, strict=True)]  # SB3's `discounts`: None
        return ReplayBufferSamples(*joined)
