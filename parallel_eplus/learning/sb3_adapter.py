"""A thin adapter from our vector envs (local or Ray) to Stable-Baselines3's VecEnv API."""

from __future__ import annotations

from typing import Any

import numpy as np
from stable_baselines3.common.vec_env import VecEnv


class SB3VecEnv(VecEnv):
    """Translates SAME_STEP autoreset infos into SB3's `terminal_observation` and `episode` keys.

    `venv` is an `EnergyPlusVectorEnv` or a `RayVectorEnv`: anything with `num_envs`, the single
    spaces, `start_all(indices)`, `step_lists(actions)` and `close()`.
    """

    def __init__(self, venv):
        self.venv = venv
        self.render_mode = None
        super().__init__(venv.num_envs, venv.single_observation_space, venv.single_action_space)
        self._actions: np.ndarray | None = None
        self._returns = np.zeros(self.num_envs)
        self._lengths = np.zeros(self.num_envs, dtype=np.int64)

    def reset(self) -> np.ndarray:
        self.reset_infos = self.venv.start_all(range(self.num_envs))
        self._returns[:] = 0
        self._lengths[:] = 0
        return self.venv.observations()

    def step_async(self, actions: np.ndarray) -> None:
        self._actions = actions

    def step_wait(self):
        obs, rewards, terminated, truncated, infos = self.venv.step_lists(self._actions)
        self._returns += rewards
        self._lengths += 1
        dones = terminated | truncated
        for i in np.flatnonzero(dones):
            self._episode_end(i, infos[i], bool(terminated[i]), bool(truncated[i]))
        return obs, rewards.astype(np.float32), dones, infos

    # -- one worker at a time (pipelining), where the vector env offers it ----------------------
    @property
    def steps_one_by_one(self) -> bool:
        """Whether `send_one`, `ready` and `receive_one` work (local workers offer them)."""
        return hasattr(self.venv, "receive_one")

    @property
    def collects_fragments(self) -> bool:
        """Whether the workers collect whole trajectory fragments themselves (Ray actors: `collect`)."""
        return hasattr(self.venv, "collect")

    def send_one(self, i: int, action: np.ndarray) -> None:
        self.venv.send_one(i, action)

    def ready(self, indices) -> list[int]:
        return self.venv.ready(indices)

    def receive_one(self, i: int) -> tuple[np.ndarray, float, bool, dict] | None:
        """Worker i's (observation, reward, done, info), with the keys `step_wait` gives SB3; None while
        its next episode starts up."""
        answer = self.venv.receive_one(i)
        if answer is None:
            return None
        obs, reward, terminated, truncated, info = answer
        self._returns[i] += reward
        self._lengths[i] += 1
        if terminated or truncated:
            self._episode_end(i, info, terminated, truncated)
        return obs, reward, terminated or truncated, info

    def _episode_end(self, i: int, info: dict, terminated: bool, truncated: bool) -> None:
        info["terminal_observation"] = info.pop("final_obs")
        info["TimeLimit.truncated"] = truncated and not terminated
        info["episode"] = {"r": float(self._returns[i]), "l": int(self._lengths[i])}
        self._returns[i] = 0
        self._lengths[i] = 0

    def close(self) -> None:
        self.venv.close()

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
