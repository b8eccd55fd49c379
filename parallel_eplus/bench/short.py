"""Short episodes (issue 39): consecutive episodes in one env against EnergyPlus alone, reset latency, and TRPO's
rate by episode length. `parallel-eplus bench --short` and studies/short-episodes/short_episodes.py run these.

1. `consecutive`: N episodes through one `EnergyPlusEnv` (a constant action, resets included, from constructing the
   env to closing it), prepared ahead (the default: forked from a template parked at the first step, episodes/fork.py),
   prepared in long-lived processes (`fork_episodes=False`) and cold (`prepare_next=False`), against EnergyPlus alone
   running the same N periods one after another in one process (alone.py: the same prepared model, the action held
   by EnergyPlus's own EMS, a new API state per run). Interleaved alone / prepared / long-lived / cold, `pairs`
   times; ratios are taken within each round and their median reported, so a machine shared with other work meets
   every side alike. Each reset's latency is kept (the first, always cold, left out).
2. `training`: TRPO `learn` steps/s with 2 workers at each episode length, the lengths interleaved round by round;
   optionally each also with long-lived processes instead of forks, and cold, right after it.
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
from parallel_eplus.buildings.weather.files import resolve_weather
from parallel_eplus.envs.env import EnergyPlusEnv

log = logging.getLogger(__name__)


def env_episodes(
    days: int, episodes: int, weather: str, prepare: bool, workdir: Path, action: float = 0.0, fork: bool = True
) -> dict:
    """Wall seconds for `episodes` consecutive episodes in one env, and each reset's seconds."""
    t0 = time.perf_counter()
    env = EnergyPlusEnv(weather=weather, run_days=days, output_dir=workdir, keep_episodes=0, energyplus_csv=False,
                        prepare_next=prepare, fork_episodes=fork)  # fmt: skip
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


ENV_MODES = {"prepared": (True, True), "long_lived": (True, False), "cold": (False, False)}  # (prepare, fork)


def consecutive(days: int, episodes: int, pairs: int, weather: str, modes: tuple[str, ...] = tuple(ENV_MODES)) -> dict:
    """`modes`: of ENV_MODES, each round in this order after EnergyPlus alone; "prepared" is the default env."""
    rows = []
    with tempfile.TemporaryDirectory(prefix="parallel-eplus-short-") as tmp:
        for k in range(pairs):
            row = {"alone": alone_episodes(days, episodes, weather, Path(tmp) / f"alone{k}")}
            for m in modes:
                row[m] = env_episodes(days, episodes, weather, ENV_MODES[m][0], Path(tmp) / f"{m}{k}",
                                      fork=ENV_MODES[m][1])  # fmt: skip
            rows.append(row)
            log.info("%d days, round %d: %s", days, k, ", ".join(f"{m} {r['wall_s']:.2f} s" for m, r in row.items()))
    med = statistics.median
    out: dict = {"days": days, "episodes": episodes, "pairs": pairs, "alone_s": med(r["alone"]["wall_s"] for r in rows)}
    for m in modes:
        resets = sorted(r for row in rows for r in row[m]["resets_s"][1:])  # the first reset is always cold
        key = "" if m == "prepared" else f"{m}_"
        out |= {
            f"{m}_s": med(r[m]["wall_s"] for r in rows),
            f"{m}_over_alone": med(r[m]["wall_s"] / r["alone"]["wall_s"] for r in rows),
            f"{key}reset_p50_ms": 1e3 * float(np.percentile(resets, 50)),
            f"{key}reset_p99_ms": 1e3 * float(np.percentile(resets, 99)),
        }  # fmt: skip
    if "long_lived" in modes and "prepared" in modes:
        out["prepared_over_long_lived"] = med(r["prepared"]["wall_s"] / r["long_lived"]["wall_s"] for r in rows)
    return out


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


def training(days: list[int], train_steps: int, pairs: int, cold: bool = False, long_lived: bool = False) -> dict:
    """TRPO steps/s with 2 workers at each episode length, the lengths interleaved round by round; with `long_lived`
    and `cold`, each length also with episodes prepared in long-lived processes (no forks) and started cold, right
    after the default run (prepared, forked). Each length's share of the year-long rate is taken within its round
    against the default year-long run."""
    from parallel_eplus.bench.config import BenchConfig
    from parallel_eplus.bench.rates import training_rate

    modes = ["prepared", *(["long_lived"] if long_lived else []), *(["cold"] if cold else [])]
    rates: dict[tuple[int, str], list[float]] = {(d, m): [] for d in days for m in modes}
    with tempfile.TemporaryDirectory(prefix="parallel-eplus-short-train-") as tmp:
        for k in range(pairs):
            for d in days:
                for m in modes:
                    cfg = BenchConfig(workers=2, train_steps=train_steps, batch_size=train_steps, ray=False)
                    prepare, fork = ENV_MODES[m]
                    rate = training_rate(cfg, Path(tmp) / f"t{d}_{m}_{k}", run_days=d, prepare_next=prepare,
                                         fork_episodes=fork)["steps_per_s"]  # fmt: skip
                    rates[d, m].append(rate)
                    log.info("TRPO, %d-day episodes, %s, round %d: %.0f steps/s", d, m, k, rate)
    year, med = max(days), statistics.median
    out: dict = {"train_rates": {f"{d}d_{m}": r for (d, m), r in rates.items()}}
    for m in modes:
        key = "" if m == "prepared" else f"{m}_"
        out |= {f"train_{d}d_{key}steps_per_s": med(rates[d, m]) for d in days}
        out |= {f"train_{d}d_{key}over_{year}d": med(a / b for a, b in zip(rates[d, m], rates[year, "prepared"],
                strict=True)) for d in days}  # fmt: skip
        if m != "prepared":
            out |= {f"train_{d}d_prepared_over_{m}": med(a / b for a, b in zip(rates[d, "prepared"], rates[d, m],
                    strict=True)) for d in days}  # fmt: skip
    return out
