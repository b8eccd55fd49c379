"""SB3's SAC with a hook on the actions it samples (`--algorithm mbpo`'s rail: model_based/mbpo.py)."""

from __future__ import annotations

from stable_baselines3 import SAC


class GuardedSAC(SAC):
    """SB3's SAC whose sampled actions a `guard(action, buffer_action)` may override before they are sent and
    stored (`--algorithm mbpo`'s rail: model_based/mbpo.py); the guard is the run's, never saved."""

    guard = None

    def _sample_action(self, learning_starts, action_noise=None, n_envs=1):
        action, buffer_action = super()._sample_action(learning_starts, action_noise, n_envs)
        if self.guard is not None:
            action, buffer_action = self.guard(action, buffer_action)
        return action, buffer_action

    def _excluded_save_params(self) -> list[str]:
        return [*super()._excluded_save_params(), "guard"]
