"""A thin adapter from our vector envs (local or Ray) to Stable-Baselines3's VecEnv API."""

from __future__ import annotations

from typing import Any

from stable_baselines3.common.vec_env import VecEnv

from parallel_eplus.learning.episode_keys import EpisodeKeys


class SB3VecEnv(EpisodeKeys, VecEnv):
    """`EpisodeKeys` as an SB3 VecEnv: the learner's view of the workers."""

    def __init__(self, venv):
        EpisodeKeys.__init__(self, venv)  # first: VecEnv's asks for render_mode
        VecEnv.__init__(self, venv.num_envs, venv.single_observation_space, venv.single_action_space)

    # SB3 asks these of every VecEnv; our workers are EnergyPlus processes, not Python envs.
    def get_attr(self, attr_name: str, indices=None) -> list[Any]:
        return [getattr(self, attr_name)] * len(self._get_indices(indices))

    def set_attr(self, attr_name: str, value: Any, indices=None) -> None:
        raise AttributeError("EnergyPlus workers have no settable attributes")

    def env_method(self, method_name: str, *args, indices=None, **kwargs) -> list[Any]:
        if method_name == "render":
            return [None] * len(self._get_indices(indices))
        raise AttributeError(f"EnergyPlus workers have no method {method_name!r}")

    def env_is_wrapped(self, wrapper_class, indices=None) -> list[bool]:
        return [False] * len(self._get_indices(indices))
