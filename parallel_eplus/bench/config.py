"""What one benchmark run measures: its period, weather, workers, repeats and action."""

from __future__ import annotations

import os
from dataclasses import dataclass

import numpy as np

from parallel_eplus.buildings.building import Building, load_building


@dataclass
class BenchConfig:
    """What one benchmark run measures: its period, weather, workers, repeats and constant action."""

    weather: str = "CA"
    raw_days: int = 365  # period for raw and env
    # EnergyPlus's cost under exploring actions varies with the season (a summer step costs up to 1.5-1.7
    # times a January one here), so the vector env and training are timed over the same simulated days.
    train_steps: int = 16384  # env steps of TRPO learn: one paper batch and its update
    vector_steps: int | None = None  # vector steps per worker; None: train_steps / workers
    batch_size: int = 16384  # the paper's; smaller only to smoke-test the benchmark itself
    workers: int = os.cpu_count() or 1
    repeats: int = 3
    action: float = 0.0  # the constant normalized action for raw and env
    ray: bool = True  # also time training through a local Ray (the Ray backend's row)
    building: str | None = None  # a spec path or built-in name; None: the data center (temp_fan)
    short: bool = False  # also short episodes (short.py): consecutive episodes, resets, TRPO by episode length
    boptest: bool = False  # also BOPTEST's API (boptest.py): what POST /advance adds per step, over `raw_days`


def bench_building(cfg: BenchConfig) -> Building:
    """The building every measurement runs: its model, actions and control step."""
    return load_building(cfg.building)


def _exploring_actions(cfg: BenchConfig, workers: int) -> np.ndarray:
    """(steps, workers, actions) drawn like an untrained policy's, the same for every measurement."""
    steps = cfg.vector_steps or cfg.train_steps // cfg.workers
    rng = np.random.default_rng(0)
    n = len(bench_building(cfg).actions)
    return np.clip(rng.normal(size=(steps, workers, n)), -1, 1).astype(np.float32)
