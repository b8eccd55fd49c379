"""The paper's evaluation protocol: the policy keeps learning while it runs each test weather.

Moriyama et al. collected their test-weather results while the network kept training, acting with the
stochastic policy. For each weather a copy of the saved model (with its observation statistics, which
keep updating) trains on that weather alone for one episode; that episode's summary is the result.
Nothing is written back to the saved model. The frozen, deterministic protocol is `sweep.run_sweep`.
"""

from __future__ import annotations

import logging
import multiprocessing
from concurrent.futures import ProcessPoolExecutor
from dataclasses import replace
from pathlib import Path

import pandas as pd
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.logger import Logger

from parallel_eplus.buildings.building import load_building
from parallel_eplus.buildings.weather.files import parse_weathers, weather_label
from parallel_eplus.evaluation.controllers import Controller, slug

log = logging.getLogger(__name__)

ONLINE_SUFFIX = ", online"


class _FirstEpisode(BaseCallback):
    """Stops learning when the first episode ends, keeping its summary (the partial batch after it is dropped)."""

    def __init__(self):
        super().__init__()
        self.summary: dict | None = None

    def _on_step(self) -> bool:
        for info in self.locals["infos"]:
            final = info.get("final_info")
            if final and "episode_summary" in final:
                self.summary = {**final["episode_summary"], "episode_dir": str(final.get("episode_dir", ""))}
        return self.summary is None


def run_online_episode(
    controller: Controller, weather: str, run_days: int, out_dir: Path, batch_size: int | None = None
) -> dict:
    """One episode of `weather` while a copy of the controller's model keeps training; returns its results row."""
    import torch as th

    from parallel_eplus.learning.algorithms import ALGORITHMS
    from parallel_eplus.learning.saved_models import load_model
    from parallel_eplus.runs.norm_stats import read_stats
    from parallel_eplus.runs.policy_files import normalization_file, run_dir_of
    from parallel_eplus.training.config import TrainConfig
    from parallel_eplus.training.train import make_vec_env

    saved = TrainConfig.from_json((run_dir_of(controller.path) / "config.json").read_text())
    if saved.algorithm not in ("trpo", "ppo"):
        raise ValueError(
            f"--online: {controller.label} is {saved.algorithm.upper()}; online evaluation is for TRPO/PPO"
        )
    label = controller.label + ONLINE_SUFFIX
    cfg = replace(
        saved, workers=1, weathers=[weather], run_days=run_days, batch_size=batch_size or saved.batch_size,
        runs_dir=str(out_dir / "online"), run_name=f"{slug(label)}-{weather_label(weather)}",
        init_from=None, backend="local", lockstep=True, keep_episodes=2, building=controller.building,
    ).resolved()  # fmt: skip
    episode_steps = run_days * load_building(cfg.building).steps_per_day  # the building's own control step
    th.set_num_threads(1)
    venv = make_vec_env(cfg)
    try:
        env = read_stats(normalization_file(controller.path)).wrap(venv, training=True)  # keeps updating
        # n_steps is the rollout buffer's size: set before SB3 builds it.
        model = load_model(ALGORITHMS[saved.algorithm], controller.path, env=env, device="cpu", n_steps=cfg.n_steps)
        model.lockstep = True
        model.set_logger(Logger(None, []))  # SB3's default logger would leave an empty SB3-<time> folder in /tmp
        stop = _FirstEpisode()
        model.learn(episode_steps + 2 * cfg.n_steps, callback=stop, reset_num_timesteps=True)
    finally:
        venv.close()
    if stop.summary is None:
        raise RuntimeError(f"online evaluation of {label} on {weather}: the episode did not finish")
    updates = episode_steps // cfg.n_steps
    log.info("%s on %s: %d updates during the episode", label, weather, updates)
    band = dict(zip(("band_low_c", "band_high_c"), load_building(cfg.building).band, strict=True))
    return {"controller": label, **stop.summary, **(band if cfg.building else {}), "online_updates": updates}


def _run(args: tuple) -> dict:
    logging.basicConfig(level=logging.WARNING)
    return run_online_episode(*args)


def run_online(
    controllers: list[Controller],
    weathers: list[str],
    run_days: int,
    workers: int,
    out_dir: Path,
    batch_size: int | None = None,
) -> pd.DataFrame:
    """`run_online_episode` for every (policy, weather), up to `workers` at once (one process each)."""
    buildings = {c.building for c in controllers if c.kind == "policy"}
    known = {k: v for b in buildings if b for k, v in load_building(b).spec.weathers.items()}
    weathers = parse_weathers(",".join(weathers), known)
    jobs = [(c, w, run_days, out_dir, batch_size) for c in controllers if c.kind == "policy" for w in weathers]
    if workers <= 1 or len(jobs) <= 1:
        rows = [run_online_episode(*job) for job in jobs]
    else:
        with ProcessPoolExecutor(min(workers, len(jobs)), mp_context=multiprocessing.get_context("spawn")) as pool:
            rows = list(pool.map(_run, jobs))
    return pd.DataFrame(rows)
