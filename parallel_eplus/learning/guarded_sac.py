"""SB3's SAC with hooks on the actions it samples: `--algorithm mbpo`'s rail (model_based/mbpo.py), and the warm-up
acted by a cloned actor (`--init-from-baseline`)."""

from __future__ import annotations

from stable_baselines3 import SAC


class GuardedSAC(SAC):
    """SB3's SAC whose sampled actions a `guard(action, buffer_action)` may override before they are sent and
    stored (`--algorithm mbpo`'s rail); with `warmup_policy`, its first `learning_starts` steps are the policy's own
    (stochastic) actions instead of uniform random ones. SB3 fills the replay buffer with random actions before the
    first update; after `--init-from-baseline` that would throw the clone away for the 10,000 steps the critic
    first learns from. Both are the run's settings (train.py sets them on every start and resume), never saved."""

    guard = None
    warmup_policy = False

    def _sample_action(self, learning_starts, action_noise=None, n_envs=1):
        starts = 0 if self.warmup_policy else learning_starts  # updates still wait for `learning_starts`
        action, buffer_action = super()._sample_action(starts, action_noise, n_envs)
        if self.guard is not None:
            action, buffer_action = self.guard(action, buffer_action)
        return action, buffer_action

    def _excluded_save_params(self) -> list[str]:
        return [*super()._excluded_save_params(), "guard", "warmup_policy"]
