"""Short episodes (issue 39): consecutive episodes in one env against EnergyPlus alone, reset latency, and TRPO's
rate by episode length. `parallel-eplus bench --short` and scripts/short_episodes.py run these.

1. `consecutive`: N episodes through one `EnergyPlusEnv` (a constant action, resets included, from constructing the
   env to closing it), prepared ahead (the default) and cold (`prepare_next=False`), against EnergyPlus alone running
   the same N periods one after another in one process (alone.py: the same prepared model, the action held by
   EnergyPlus's own EMS, a new API state per run). Interleaved alone / prepared / cold, `pairs` times; ratios are
   taken within each round and their median reported, so a machine shared with other work meets every side alike.
   Each reset's latency is kept (the first, always cold, left out).
2. `training`: TRPO `learn` steps/s with 2 workers at each episode length, the lengths interleaved round by round.
"""

from __future__ import annotations

import logging
import statistics
import tempfile
import time
from pathlib import Path

import numpy as np

from parallel_eplus.bench.alone import alone_model, run_alone
from parallel_eplus.bench.raw import _physical
from parallel_eplus.buildings.building import load_building
from parallel_eplus.buildings.weather import resolve_weather
from parallel_eplus.envs.env import EnergyPlusEnv

log = logging.getLogger(__name__)


def env_episodes(days: int, episodes: int, weather: str, prepare: bool, workdir: Path, action: float = 0.0) -> dict:
    """Wall seconds for `episodes` consecutive episodes in one env, and each reset's seconds."""
    t0 = time.perf_counter()
    env = EnergyPlusEnv(weather=weather, run_days=days, output_dir=workdir, keep_episodes=0, energyplus_csv=False,
                        prepare_next=prepare)  # fmt: skip
    a = np.full(env.action_space.shape, action, dtype=np.float32)
    resets = []
    try:
        for _ in range(episodes):
            t = time.perf_counter()
            env.reset()
            resets.append(time.perf_counter() - t)
            terminated = False
            while not terminated:
                _, _, terminated, _, _ = env.step(a)
    finally:
        env.close()
    return {"wall_s": time.perf_counter() - t0, "resets_s": resets}


def alone_episodes(days: int, episodes: int, weather: str, workdir: Path, action: float = 0.0) -> dict:
    building = load_building(None)
    idf = alone_model(building, workdir / "model.idf", days, _physical([action] * len(building.actions)))
    epw = building.spec.weathers.get(weather) or resolve_weather(weather)
    return run_alone(workdir / "out", [(idf, epw)] * episodes)


def consecutive(days: int, episodes: int, pairs: int, weather: str) -> dict:
    rows = []
    with tempfile.TemporaryDirectory(prefix="parallel-eplus-short-") as tmp:
        for k in range(pairs):
            alone = alone_episodes(days, episodes, weather, Path(tmp) / f"alone{k}")
            prepared = env_episodes(days, episodes, weather, True, Path(tmp) / f"prep{k}")
            cold = env_episodes(days, episodes, weather, False, Path(tmp) / f"cold{k}")
            rows.append({"alone": alone, "prepared": prepared, "cold": cold})
            log.info("%d days, round %d: alone %.2f s, prepared %.2f s, cold %.2f s", days, k,
                         alone["wall_s"], prepared["wall_s"], cold["wall_s"])  # fmt: skip
    med = statistics.median
    resets = sorted(r for row in rows for r in row["prepared"]["resets_s"][1:])  # the first reset is always cold
    cold_resets = sorted(r for row in rows for r in row["cold"]["resets_s"][1:])
    return {
        "days": days, "episodes": episodes, "pairs": pairs,
        "alone_s": med(r["alone"]["wall_s"] for r in rows),
        "prepared_s": med(r["prepared"]["wall_s"] for r in rows),
        "cold_s": med(r["cold"]["wall_s"] for r in rows),
        "prepared_over_alone": med(r["prepared"]["wall_s"] / r["alone"]["wall_s"] for r in rows),
        "cold_over_alone": med(r["cold"]["wall_s"] / r["alone"]["wall_s"] for r in rows),
        "reset_p50_ms": 1e3 * float(np.percentile(resets, 50)), "reset_p99_ms": 1e3 * float(np.percentile(resets, 99)),
        "cold_reset_p50_ms": 1e3 * float(np.percentile(cold_resets, 50)),
        "cold_reset_p99_ms": 1e3 * float(np.percentile(cold_resets, 99)),
    }  # fmt: skip


def parked_resets(days: int, resets: int, weather: str, workdir: Path) -> dict:
    """Reset latency when the prepared episode is parked at its first step (the episode before it outlasted its
    preparation, as in training): what `reset()` itself costs, p50 and p99 over `resets` resets."""
    env = EnergyPlusEnv(weather=weather, run_days=days, output_dir=workdir, keep_episodes=0, energyplus_csv=False)
    a = np.zeros(env.action_space.shape, dtype=np.float32)
    took = []
    try:
        env.reset()
        for _ in range(resets):
            terminated = False
            while not terminated:
                _, _, terminated, _, _ = env.step(a)
            while env.sim.prepared is not None and not env.sim.prepared.parked():
                time.sleep(0.005)
            t = time.perf_counter()
            env.reset()
            took.append(time.perf_counter() - t)
            assert env.sim._from_prepared
    finally:
        env.close()
    ms = 1e3 * np.array(took)
    return {"parked_reset_p50_ms": float(np.percentile(ms, 50)), "parked_reset_p99_ms": float(np.percentile(ms, 99)),
            "parked_resets": resets}  # fmt: skip


def training(days: list[int], train_steps: int, pairs: int, cold: bool = False) -> dict:
    """TRPO steps/s with 2 workers at each episode length, the lengths interleaved round by round; with `cold`,
    each length also with every episode started cold (prepare_next off), right after the prepared run."""
    from parallel_eplus.bench.config import BenchConfig
    from parallel_eplus.bench.rates import training_rate

    modes = [True, False] if cold else [True]
    rates: dict[tuple[int, bool], list[float]] = {(d, m): [] for d in days for m in modes}
    with tempfile.TemporaryDirectory(prefix="parallel-eplus-short-train-") as tmp:
        for k in range(pairs):
            for d in days:
                for m in modes:
                    cfg = BenchConfig(workers=2, train_steps=train_steps, batch_size=train_steps, ray=False)
                    where = Path(tmp) / f"t{d}_{m}_{k}"
                    rates[d, m].append(training_rate(cfg, where, run_days=d, prepare_next=m)["steps_per_s"])
                    log.info("TRPO, %d-day episodes, %s, round %d: %.0f steps/s", d,
                             "prepared" if m else "cold", k, rates[d, m][-1])  # fmt: skip
    year, med = max(days), statistics.median
    out = {f"train_{d}d_steps_per_s": med(rates[d, True]) for d in days}
    out |= {f"train_{d}d_over_{year}d": med(a / b for a, b in zip(rates[d, True], rates[year, True], strict=True))
            for d in days}  # fmt: skip
    if cold:
        out |= {f"train_{d}d_cold_steps_per_s": med(rates[d, False]) for d in days}
        out |= {f"train_{d}d_prepared_over_cold": med(a / b for a, b in zip(rates[d, True], rates[d, False],
                strict=True)) for d in days}  # fmt: skip
    return out
