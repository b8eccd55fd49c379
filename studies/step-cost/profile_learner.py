"""The learner's side of one control step: from a worker's observation arriving to its next action sent, phase by
phase, in a real training run (docs/speed.md quotes its output), beside what EnergyPlus did meanwhile.

    PYTHONPATH=. .venv/bin/python studies/step-cost/profile_learner.py --workers 1

The learner's methods on that path (`ready`, `receive_one`, `NumpyPolicy.sample`, `send_one`) are wrapped with
`perf_counter_ns` marks (~1 µs each); EnergyPlus's C side reports how long it computed ahead of needing each action
and how long it then waited at its actuators (`ahead_s`, `waited_s` in each episode's energyplus.log).
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np

from parallel_eplus.engine.episode import bridge_counters
from parallel_eplus.learning import sb3_adapter
from parallel_eplus.runs import numpy_policy
from parallel_eplus.training.config import TrainConfig
from parallel_eplus.training.train import train

PHASES = ("receive", "normalize and bookkeeping", "policy", "clip", "send")


def _wrap(cls, name: str, tag: str, marks: list) -> None:
    method = getattr(cls, name)

    def timed(*args, **kwargs):
        t0 = time.perf_counter_ns()
        out = method(*args, **kwargs)
        marks.append((tag, t0, time.perf_counter_ns()))
        return out

    setattr(cls, name, timed)


def _steps(marks: list) -> np.ndarray:
    """µs per phase for each step whose observation came in on its own and whose action went out after it."""
    rows, cur = [], {}
    for tag, t0, t1 in marks:
        if tag == "ready":
            cur = {"ready": t1}
        elif tag in ("receive", "sample", "send") and tag not in cur and ("ready" in cur):
            cur[tag] = (t0, t1)
            if tag == "send" and "receive" in cur and "sample" in cur:
                r, s, o = cur["receive"], cur["sample"], cur["send"]
                rows.append([r[1] - r[0], s[0] - r[1], s[1] - s[0], o[0] - s[1], o[1] - o[0]])
                cur = {}
    return np.array(rows) / 1e3


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--workers", type=int, default=1)
    p.add_argument("--steps", type=int, default=16384)
    p.add_argument("--run-days", type=int, default=64)
    args = p.parse_args()
    marks: list = []
    env, policy = sb3_adapter.SB3VecEnv, numpy_policy.NumpyPolicy
    for cls, name, tag in ((env, "ready", "ready"), (env, "receive_one", "receive"), (policy, "sample", "sample"),
                           (env, "send_one", "send")):  # fmt: skip
        _wrap(cls, name, tag, marks)
    with tempfile.TemporaryDirectory(prefix="parallel-eplus-profile-") as tmp:
        cfg = TrainConfig(workers=args.workers, weathers=["CA"], run_days=args.run_days, timesteps=args.steps,
                          batch_size=args.steps, seed=0, run_name="profile", runs_dir=str(Path(tmp, "runs")),
                          tensorboard_dir=str(Path(tmp, "tb")), checkpoint_every=10**9)  # fmt: skip
        train(cfg, progress=False)
        counters: dict[str, float] = {}
        for log in Path(tmp, "runs").rglob("energyplus.log"):
            for key, value in bridge_counters(log.parent).items():
                counters[key] = counters.get(key, 0.0) + value
    d = _steps(marks)
    print(f"{args.workers} worker(s), {len(d)} steps timed (µs per step, median / mean)")
    for phase, column in zip(PHASES, d.T, strict=True):
        print(f"  learner {phase:28s} {np.median(column):7.1f} {column.mean():7.1f}")
    total = d.sum(axis=1)
    print(f"  learner turnaround, observation in to action out {np.median(total):7.1f} {total.mean():7.1f}")
    per_step = {k: v / (counters.get("exchanges") or float("nan")) * 1e6 for k, v in counters.items()}
    print(
        f"  EnergyPlus: computed ahead {per_step.get('ahead_s', 0.0):.1f}, then waited at its actuators "
        f"{per_step.get('waited_s', 0.0):.1f}, of a step of {per_step.get('stepping_s', 0.0):.1f}"
    )


if __name__ == "__main__":
    main()
