"""The pipelined collection loop: each worker gets its next action as soon as its own observation arrives.

One loop serves two places. The local learner runs it over its own workers, writing into SB3's
rollout buffer and calling the callbacks as vector steps complete (`rollout.py`). A Ray actor runs it
over the workers of its node, writing into a trajectory fragment that goes back to the learner in one
reply (`fragments.py`). Both hand it a *sink*: anything with the rollout buffer's arrays
(`observations`, `actions`, `rewards`, `episode_starts`, `values`, `log_probs`, each `[step, worker, ...]`).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from parallel_eplus.runs.numpy_policy import NumpyPolicy

# What the loop writes per transition: the rollout buffer's own array names.
SINK_ARRAYS = ("observations", "actions", "rewards", "episode_starts", "values", "log_probs")
# Arrays a sink may also have, filled from each step's info (array, info key): the comfort constraint's cost and
# counts (learning/lagrangian.py), reported by the env when comfort is a constraint.
SIDE_ARRAYS = (("costs", "comfort_cost"), ("comfort_out", "comfort_out"), ("comfort_zones", "comfort_zones"))


def step_value(info: dict, key: str) -> float:
    """What a step reported under `key`: an episode's last step in `final_info` (the vector env's autoreset puts the
    next episode's first info on top), every other step in `info` itself; 0 where it reported nothing."""
    final = info.get("final_info")
    return (info if final is None else final).get(key, 0.0)


def run_pipeline(
    env,
    policy: NumpyPolicy,
    sink,
    n_steps: int,
    obs: np.ndarray,
    starts: np.ndarray,
    rngs: list[np.random.Generator],
    bounds: tuple[np.ndarray, np.ndarray],
    gamma: float,
    observe: Callable[[int, np.ndarray], np.ndarray],
    normalize_terminal: Callable[[np.ndarray], np.ndarray] | None,
    on_vector_step: Callable[[list[dict], np.ndarray], bool],
) -> bool:
    """Collect `n_steps` transitions per worker of `env` (an `EpisodeKeys` stepping one by one) into `sink`.

    `obs` (as the policy sees it) and `starts` (each worker's last `done`) are updated in place.
    `observe(i, raw)` returns worker i's new observation as the policy sees it (normalizing it, and
    updating whatever statistics the caller keeps); `normalize_terminal` does the same, without
    statistics, for an episode's last observation. `on_vector_step(infos, dones)` runs, in order, for
    every vector step all workers have made; it returns False to stop (the loop then returns False).
    """
    n = env.num_envs
    low, high = bounds
    step = [0] * n
    step_infos: list[list[dict]] = [[{} for _ in range(n)] for _ in range(n_steps)]
    step_dones = np.zeros((n_steps, n), dtype=bool)
    side = [(getattr(sink, name), key) for name, key in SIDE_ARRAYS if getattr(sink, name, None) is not None]

    def act(i: int) -> None:
        t = step[i]
        actions, values, log_probs = policy.sample(obs[i : i + 1], rngs[i : i + 1])
        env.send_one(i, np.clip(actions[0], low, high))  # first: the worker waits for nothing else
        sink.observations[t, i] = obs[i]  # the buffer keeps the unclipped action, as in SB3
        sink.actions[t, i] = actions[0]
        sink.episode_starts[t, i] = starts[i]
        sink.values[t, i] = values[0]
        sink.log_probs[t, i] = log_probs[0]

    for i in range(n):
        act(i)
    pending, reported = set(range(n)), 0
    while pending:
        for i in env.ready(pending):
            answer = env.receive_one(i)
            if answer is None:  # its next episode is starting up: served when it is ready
                continue
            new_obs, reward, done, info = answer
            new_obs = observe(i, new_obs)
            if done and "terminal_observation" in info:
                if normalize_terminal is not None:
                    info["terminal_observation"] = normalize_terminal(info["terminal_observation"])
                if info.get("TimeLimit.truncated", False):  # a cut episode: bootstrap (SB3 issue #633)
                    reward += gamma * policy.value(info["terminal_observation"][None])[0]
            t = step[i]
            obs[i], starts[i] = new_obs, done
            step[i] = t + 1
            if step[i] < n_steps:
                act(i)  # the worker's next action before this step's bookkeeping: it waits for nothing else
            else:
                pending.discard(i)
            sink.rewards[t, i] = reward
            for array, key in side:
                array[t, i] = step_value(info, key)
            step_infos[t][i], step_dones[t, i] = info, done
        while reported < min(step):  # vector steps every worker has made, for the callbacks
            if not on_vector_step(step_infos[reported], step_dones[reported]):
                return False
            step_infos[reported] = []
            reported += 1
    return True
