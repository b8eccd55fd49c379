"""Record the data center's behaviour on a fixed action sequence (2 days, CA) as a CSV fixture.

Run once BEFORE the building moves into a spec file; tests/test_building_fixture.py replays the same actions
and asserts identical observations, rewards and power, so the move is proven to change nothing.
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd

from parallel_eplus.buildings.datacenter import observation_names
from parallel_eplus.envs.env import EnergyPlusEnv

OUT = Path(__file__).resolve().parents[1] / "tests" / "data" / "datacenter_2zone_ca_2days.csv"


def fixed_actions(step: int, n: int) -> np.ndarray:
    """Deterministic, varied actions in [-1, 1] (no RNG: a smooth sweep plus a step pattern)."""
    base = (-0.5, -0.5, 0.2, 0.2)  # about 17.5 C supply and 4.9 kg/s: a physically sane neighbourhood
    square = 0.05 if (step // 8) % 2 else -0.05
    return np.array([base[k] + 0.1 * np.sin(0.05 * step + k) + square for k in range(n)], np.float32)


def main() -> None:
    env = EnergyPlusEnv(weather="CA", model="temp_fan", run_days=2, output_dir="/tmp/pe-fixture")
    names = observation_names()
    obs, _ = env.reset()
    rows, step, done = [], 0, False
    while not done:
        action = fixed_actions(step, env.action_space.shape[0])
        obs, reward, done, _, info = env.step(action)
        rows.append([step, *action.tolist(), *np.asarray(obs, float).tolist(), float(reward)])
        step += 1
    env.close()
    n_obs = len(rows[0]) - 2 - env.action_space.shape[0]
    obs_cols = list(names) if len(names) == n_obs else [f"obs{i}" for i in range(n_obs)]
    cols = ["step", *[f"action{k}" for k in range(env.action_space.shape[0])], *obs_cols, "reward"]
    commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True).stdout.strip()
    OUT.parent.mkdir(parents=True, exist_ok=True)
    with OUT.open("w") as f:
        f.write(f"# produced by tools/make_building_fixture.py at commit {commit} (temp_fan, CA, 2 days)\n")
        pd.DataFrame(rows, columns=cols).to_csv(f, index=False, float_format="%.17g")
    print(f"wrote {OUT} ({len(rows)} steps)", file=sys.stderr)


if __name__ == "__main__":
    main()
