"""`train --overlap`: the workers collect batch k+1 while the learner updates on batch k (learning/overlap.py).

Each learner batch is checked against what the workers themselves recorded (every step's reward, temperatures and
whether comfort applied, in their episodes' step tables): every transition appears once, in its worker's column,
in order, across the batch boundaries the overlap crosses; the comfort constraint's side arrays sit on the same
rows; the log-probabilities are the behaviour policy's and the values the current critic's.
"""

from __future__ import annotations

import threading

import numpy as np
import pandas as pd
import pytest

from parallel_eplus.buildings.building import load_building
from parallel_eplus.engine.episode import read_steps
from parallel_eplus.learning.rollout import NumpyRollouts
from parallel_eplus.runs.numpy_policy import NumpyPolicy
from parallel_eplus.training.config import ComfortConstraint
from parallel_eplus.training.train import train

from .test_train import scalars, small_config

N_STEPS = 72  # per worker and batch: one-day episodes (96 steps) end inside batches and across their ends
BATCHES = 4  # 288 steps per worker: three whole episodes


def _watch_batches(monkeypatch) -> list[dict]:
    """Every batch as the learner saw it before charging comfort and computing advantages, with the policy then."""
    batches: list[dict] = []
    charge = NumpyRollouts._charge_comfort

    def watched(self, buffer):
        keys = ("rewards", "episode_starts", "observations", "actions", "log_probs", "values", "costs",
                "comfort_out", "comfort_zones")  # fmt: skip
        batches.append({k: getattr(buffer, k).copy() for k in keys} | {"policy": NumpyPolicy(self.policy)})
        return charge(self, buffer)

    monkeypatch.setattr(NumpyRollouts, "_charge_comfort", watched)
    return batches


@pytest.mark.slow
@pytest.mark.parametrize(("backend", "algorithm"), [("local", "trpo"), ("ray", "trpo"), ("local", "ppo")])
def test_overlapped_batches_hold_every_workers_steps_once_in_order_with_their_costs(
    tmp_path, no_leaks, monkeypatch, backend, algorithm
):
    if backend == "ray":
        pytest.importorskip("ray")
    margin = 0.5
    cfg = small_config(tmp_path, f"overlap-{backend}-{algorithm}", weathers=["CA"], run_days=1, batch_size=2 * N_STEPS,
                       timesteps=BATCHES * 2 * N_STEPS, keep_episodes=10, overlap=True, backend=backend,
                       workers_per_actor=1, comfort=ComfortConstraint(target_pct=99.0, margin_c=margin),
                       algorithm=algorithm)  # fmt: skip
    batches = _watch_batches(monkeypatch)
    train(cfg, progress=False)
    assert not [t for t in threading.enumerate() if t.name == "parallel-eplus-collect"]
    assert len(batches) == BATCHES

    run = tmp_path / "runs" / cfg.run_name
    episodes = pd.read_csv(run / "episodes.csv")
    assert len(episodes) == 6 and episodes["timesteps"].max() == BATCHES * 2 * N_STEPS
    assert episodes.groupby("worker")["episode"].apply(sorted).to_dict() == {w: [1, 2, 3] for w in (0, 1)}
    tags = scalars(tmp_path / "tb" / cfg.run_name)
    assert tags["throughput/episodes"][-1].value == 6
    for tag in ("throughput/learner_idle_share", "throughput/workers_idle_share"):
        assert len(tags[tag]) == BATCHES - 1 and all(0.0 <= e.value <= 1.0 for e in tags[tag]), tag

    comfort = load_building(None).comfort
    columns = []
    for worker in (0, 1):
        steps = pd.concat([read_steps(d) for d in sorted((run / "episodes").glob(f"worker-{worker}/episode-*"))])
        assert len(steps) == BATCHES * N_STEPS  # three whole episodes
        column = {k: np.concatenate([b[k][:, worker] for b in batches]) for k in ("rewards", "episode_starts",
                                                                                   "costs", "comfort_out",
                                                                                   "comfort_zones")}  # fmt: skip
        # Every step the worker made, once and in order: the learner's column is the worker's own record.
        np.testing.assert_allclose(column["rewards"], steps["reward"].to_numpy(), rtol=1e-5, atol=1e-6)
        assert np.flatnonzero(column["episode_starts"]).tolist() == [0, 96, 192]
        # The constraint's arrays sit on the same rows as the rewards.
        temps = steps[list(comfort.temperatures)].to_numpy()
        applies = steps["comfort_applies"].to_numpy() > 0
        expected = np.array(
            [comfort.cost(tuple(t), margin) if a else (0.0, 0) for t, a in zip(temps, applies, strict=True)]
        )
        np.testing.assert_allclose(column["costs"], expected[:, 0], atol=1e-6)
        np.testing.assert_array_equal(column["comfort_out"], expected[:, 1])
        np.testing.assert_array_equal(column["comfort_zones"], np.where(applies, len(comfort.temperatures), 0))
        assert column["costs"].max() > 0  # an untrained policy leaves the band: the check has teeth
        columns.append(column["rewards"])
    assert not np.allclose(*columns)  # one weather, each worker's own noise: a swapped column would show

    # Batch k+1 was collected by the policy the update on batch k started from: the buffer keeps that policy's
    # log-probabilities (the importance ratio's denominator), and the current critic's values.
    for k, batch in enumerate(batches):
        obs = batch["observations"].reshape(2 * N_STEPS, -1)
        actions = batch["actions"].reshape(2 * N_STEPS, -1)
        behaviour = batches[max(k - 1, 0)]["policy"]
        current = batch["policy"]
        np.testing.assert_allclose(batch["log_probs"].reshape(-1), behaviour.log_prob(actions, behaviour.mean(obs)),
                                   rtol=1e-4, atol=1e-4)  # fmt: skip
        np.testing.assert_allclose(batch["values"].reshape(-1), current.value(obs), rtol=1e-4, atol=1e-4)
        if k >= 1:
            assert not np.allclose(batch["log_probs"].reshape(-1), current.log_prob(actions, current.mean(obs)),
                                   rtol=1e-4, atol=1e-4)  # fmt: skip
