"""SB3's episode keys on our vector envs' autoreset infos, without SB3: what a Ray actor collecting on its node needs
(learning/ray_actor.py), whose process then imports neither SB3 nor torch (~3 s of CPU and hundreds of MB less per
actor). The learner's `SB3VecEnv` (sb3_adapter.py) is this as an SB3 VecEnv.
"""

from __future__ import annotations

import numpy as np


class EpisodeKeys:
    """Translates SAME_STEP autoreset infos into SB3's `terminal_observation` and `episode` keys.

    `venv` is an `EnergyPlusVectorEnv` or a `RayVectorEnv`: anything with `num_envs`, the single
    spaces, `start_all(indices)`, `step_lists(actions)` and `close()`.
    """

    def __init__(self, venv):
        self.venv = venv
        self.render_mode = None
        self.num_envs = venv.num_envs
        self.observation_space, self.action_space = venv.single_observation_space, venv.single_action_space
        self.reset_infos: list[dict] = [{} for _ in range(self.num_envs)]
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
