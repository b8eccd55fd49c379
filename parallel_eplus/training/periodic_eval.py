"""Evaluation during training: the frozen, deterministic policy on validation weathers, every N env steps.

The episodes run through the evaluation sweep's own code (evaluation/sweep.py: `Controller`, `run_local`), so a
figure here means what `evaluate` would report for the same policy, weathers and days. On 2 cores they run
between batches (the training workers wait, holding their observation); with Ray too, for now.

`Evaluator` is the algorithm-free part: give it any `act(observation) -> action` (a policy's deterministic
predict over normalized observations, with the statistics to normalize them) and the steps so far; it runs the
episodes, reads the KPIs from the summaries the evaluation returns, compares energy with the built-in controller
(run once per weather and cached in the run folder), appends runs/<name>/evaluations.csv, and says whether this
is the best evaluation so far and whether the target was first met now (runs/<name>/target.json).
`PeriodicEval` is the SB3 callback around it; it also logs `eval/...` to TensorBoard and saves the best policy as
runs/<name>/best/model.zip with its vecnormalize.npz (eval_target.py defines "best").
"""

from __future__ import annotations

import dataclasses
import json
import logging
import math
import shutil
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd
from stable_baselines3.common.callbacks import BaseCallback

from parallel_eplus import io
from parallel_eplus.buildings.building import Building, load_building
from parallel_eplus.buildings.weather.files import weather_label
from parallel_eplus.engine.config import SimulationConfig
from parallel_eplus.evaluation.controllers import BASELINE_LABEL, Controller
from parallel_eplus.evaluation.sweep import _job_config, run_local
from parallel_eplus.runs.run_files import ALL_WEATHERS as ALL
from parallel_eplus.runs.run_files import BEST_DIR, EVALUATIONS_FILE, TARGET_FILE, read_status
from parallel_eplus.training.eval_target import ENERGY, EvalSettings, meets, parse_target, score

log = logging.getLogger(__name__)

BASELINE_FILE = "eval_baseline.json"
SKIP = {"episode", "steps", "run_days", "complete"}  # summary numbers that are not KPIs


@dataclass
class EvalResult:
    steps: int
    kpis: dict  # means over the weathers (and `score`)
    per_weather: dict[str, dict]
    best: bool  # the best evaluation so far (eval_target.score)
    target_met_now: bool  # the first evaluation that meets the target


def _kpis(summary: dict) -> dict:
    return {k: float(v) for k, v in summary.items() if isinstance(v, (int, float)) and not isinstance(v, bool)
            and k not in SKIP}  # fmt: skip


def _energy(kpis: dict) -> float:
    return kpis.get("energy_kwh", kpis.get("power_kw", math.nan))


class Evaluator:
    """Runs and records the evaluations of one run (any algorithm's)."""

    def __init__(self, run_dir: Path, settings: EvalSettings, sim: SimulationConfig, weathers: list[str],
                 workers: int, building: Building | None = None):  # fmt: skip
        """`building`: `sim.building` as the run resolved it (None: resolved here)."""
        self.run_dir, self.settings, self.sim = Path(run_dir), settings, sim
        self.building = building or load_building(sim.building)
        self.weathers = settings.weathers or weathers
        self.days = settings.days or sim.run_days
        self.workers = max(1, min(workers, len(self.weathers)))
        self.terms = parse_target(settings.target)
        self.csv = self.run_dir / EVALUATIONS_FILE
        self.best_score, self.target = -math.inf, self._read_json(TARGET_FILE)
        self._last_step: int | None = None
        if self.csv.is_file():  # a resumed run keeps its evaluations, its best and its target's step
            done = pd.read_csv(self.csv)
            means = done[done["weather"] == ALL]
            if len(means) and "score" in means:
                self.best_score = float(means["score"].max())

    def _read_json(self, name: str) -> dict | None:
        path = self.run_dir / name
        return json.loads(path.read_text()) if path.is_file() else None

    @property
    def last_step(self) -> int:
        """The step of the newest evaluation (-1: none), read once (SAC asks every vector step)."""
        if self._last_step is None:
            done = self.csv.is_file() and pd.read_csv(self.csv, usecols=["timesteps"])["timesteps"]
            self._last_step = int(done.max()) if done is not False and len(done) else -1
        return self._last_step

    def _config(self, controller: Controller, weather: str, scenario: str, out: Path) -> SimulationConfig:
        folder = out if scenario == "start" else out / scenario
        cfg = _job_config(controller, weather, self.sim.building, self.days, self.sim.reward, folder)
        model = "baseline" if controller.kind == "baseline" else self.sim.model
        # the run's own objective (what the reward's energy term counts); the weather as it is, without noise
        cfg = dataclasses.replace(cfg, model=model, step_timeout_s=self.sim.step_timeout_s, keep_episodes=1,
                                  objective=self.sim.objective)  # fmt: skip
        if scenario != "start":  # BOPTEST's two weeks of this weather, after a week's warm-up
            p = self._periods(scenario)[weather_label(weather)]
            cfg.run_days, cfg.start_day, cfg.start_weekday, cfg.warmup_days = (
                p.run_days, p.start_day, p.weekday, p.warmup_days
            )  # fmt: skip
        return cfg

    def _periods(self, scenario: str) -> dict:
        """Each weather's period for a BOPTEST scenario, from a year of the built-in controls (once per run)."""
        from parallel_eplus.evaluation.scenarios import find_periods

        return find_periods(scenario, self.weathers, self.building, self.run_dir / "eval-periods", self.workers,
                            progress=False)  # fmt: skip

    def _run(self, controller: Controller, cases: list[tuple[str, str]], out: Path) -> dict[str, dict]:
        """`cases`: (weather, scenario) pairs; rows keyed `_case(weather, scenario)`."""
        jobs = [(controller, self._config(controller, w, s, out)) for w, s in cases]
        rows, _ = run_local(jobs, min(self.workers, len(jobs)), _NoBar(), building=self.building)

        def scenario_of(row: dict) -> str:  # a period's episodes run in a folder of its name (`_config`)
            return next((s for s in self.settings.scenarios if s in Path(row["episode_dir"]).parts), "start")

        return {_case(str(r["weather"]), scenario_of(r)): r for r in rows}

    @property
    def cases(self) -> list[tuple[str, str]]:
        return [(w, s) for w in self.weathers for s in self.settings.scenarios]

    def baseline(self) -> dict[str, dict]:
        """The built-in controller's KPIs per evaluation weather and period: run once, then read from the run
        folder."""
        path = self.run_dir / BASELINE_FILE
        cached = json.loads(path.read_text()) if path.is_file() else {}
        key = lambda w, s: f"{weather_label(w)}|{self.days}" + ("" if s == "start" else f"|{s}")  # noqa: E731
        missing = [(w, s) for w, s in self.cases if key(w, s) not in cached]
        if missing:
            log.info("evaluation: the built-in controller on %s, once", ", ".join(_case(w, s) for w, s in missing))
            out = self.run_dir / "eval-episodes" / "baseline"
            rows = self._run(Controller(BASELINE_LABEL, "baseline"), missing, out)
            cached |= {key(w, s): _kpis(rows[_case(weather_label(w), s)]) for w, s in missing}
            io.write_text(path, json.dumps(cached, indent=2))
            shutil.rmtree(out, ignore_errors=True)
        return {_case(weather_label(w), s): cached[key(w, s)] for w, s in self.cases}

    def evaluate(self, act: Callable[[np.ndarray], np.ndarray], steps: int, wall_s: float,
                 features: tuple[bool, bool]) -> EvalResult:  # fmt: skip
        """`act`: a batch of raw observations (n, obs) -> actions (n, act), deterministic."""
        controller = Controller(
            "Policy", "policy", time_features=features[0], schedule_features=features[1],
            rbc_target_c=self.sim.rbc_target_c, residual_scale=self.sim.residual_scale,
            residual_space=self.sim.residual_space, building=self.sim.building, run="eval",
            forecast_hours=self.sim.forecast_hours, forecast_error=self.sim.forecast_error,
            act=lambda obs, info: act(obs[None, :])[0],
        )  # fmt: skip
        return self.evaluate_controller(controller, steps, wall_s)

    def evaluate_controller(self, controller: Controller, steps: int, wall_s: float) -> EvalResult:
        """Any frozen controller on the validation weathers (a model-based run's planner: training/mpc.py)."""
        base = self.baseline()
        out = self.run_dir / "eval-episodes" / "latest"
        shutil.rmtree(out, ignore_errors=True)
        t0 = time.monotonic()
        rows = self._run(controller, self.cases, out)
        eval_s = time.monotonic() - t0
        per_weather = {}
        for weather, row in rows.items():
            kpis = _kpis(row)
            kpis[ENERGY] = 100 * (_energy(kpis) / _energy(base[weather]) - 1)
            per_weather[weather] = kpis
        means = {k: float(np.mean([p[k] for p in per_weather.values() if k in p])) for k in next(iter(
            per_weather.values()))}  # fmt: skip
        means["score"] = score(means, self.terms)
        means["target_met"] = float(meets(means, self.terms))
        best = means["score"] > self.best_score
        self.best_score = max(self.best_score, means["score"])
        first = bool(means["target_met"]) and self.target is None
        if first:
            self.target = {"target": self.settings.target, "timesteps": steps, "wall_s": round(wall_s, 1),
                           "kpis": means}  # fmt: skip
            io.write_text(self.run_dir / TARGET_FILE, json.dumps(self.target, indent=2))
            log.info("target %s met at step %d (%.0f s of wall time)", self.settings.target, steps, wall_s)
        stamp = {"timesteps": steps, "wall_s": round(wall_s, 1), "eval_s": round(eval_s, 1)}
        table = pd.DataFrame([{**stamp, "weather": ALL, **means}] + [{**stamp, "weather": w, **k}
                                                                       for w, k in per_weather.items()])  # fmt: skip
        if self.csv.is_file():
            table = pd.concat([pd.read_csv(self.csv), table], ignore_index=True)
        io.write_text(self.csv, table.to_csv(index=False))
        self._last_step = steps
        log.info("evaluation at step %d: %s%s", steps, ", ".join(f"{k} {means[k]:.2f}" for k in
                 ("in_band_pct", ENERGY, "reward_mean") if k in means), " (best so far)" if best else "")  # fmt: skip
        return EvalResult(steps, means, per_weather, best, first)


def record(result: EvalResult, logger, save_best: Callable[[], None], run_dir: Path) -> None:
    """An evaluation's figures to TensorBoard (`eval/...`, each weather's under its name); the best so far saved by
    `save_best` into best/ with its figures (best/evaluation.json)."""
    for key, value in result.kpis.items():
        logger.record(f"eval/{key}", value)
    for weather, kpis in result.per_weather.items():
        for key in ("in_band_pct", ENERGY, "reward_mean", "power_kw"):
            if key in kpis:
                logger.record(f"eval/{weather}/{key}", kpis[key])
    logger.dump(result.steps)
    if result.best:
        save_best()
        io.write_text(run_dir / BEST_DIR / "evaluation.json",
                      json.dumps({"timesteps": result.steps, **result.kpis}, indent=2))  # fmt: skip


def _case(weather: str, scenario: str) -> str:
    """An evaluation episode's name: its weather, and its BOPTEST period where it has one (`CA peak_cool`)."""
    return weather if scenario == "start" else f"{weather} {scenario}"


class _NoBar:
    def update(self, n: int = 1) -> None: ...
    def set_postfix(self, **kw) -> None: ...


class PeriodicEval(BaseCallback):
    """SB3's side: between batches, once `every` env steps have passed since the last evaluation (at the first
    batch boundary at or after each multiple of `every`), and at the end of training."""

    def __init__(self, evaluator: Evaluator, features: tuple[bool, bool], save_best: Callable[[Path], None]):
        super().__init__()
        self.evaluator, self.features, self.save_best = evaluator, features, save_best
        self.every = evaluator.settings.every
        self.latest: dict = {}  # the newest evaluation's means (a sweep's trial reports them to Ray Tune)
        self._wall0 = 0.0
        self._t0 = time.monotonic()

    def _due(self) -> bool:
        last = self.evaluator.last_step
        return self.num_timesteps > last and self.num_timesteps // self.every > max(last, 0) // self.every

    def _on_training_start(self) -> None:
        self._wall0 = float((read_status(self.evaluator.run_dir) or {}).get("wall_s", 0.0))
        self._t0 = time.monotonic()
        if self.evaluator.terms:
            self.evaluator.baseline()  # at the start: the reference the target's energy is measured against

    def _on_rollout_start(self) -> None:  # the previous batch's update is done: the policy is the newest
        if self._due():
            self.run_now()

    def _on_training_end(self) -> None:
        if self.num_timesteps > self.evaluator.last_step and self._due():
            self.run_now()

    def run_now(self) -> EvalResult:
        policy, env = self.model.policy, self.model.get_vec_normalize_env()
        from parallel_eplus.runs.norm_stats import NormStats

        stats = NormStats.of(env) if env is not None else None

        def act(obs: np.ndarray) -> np.ndarray:
            action, _ = policy.predict(stats.normalize_obs(obs) if stats else obs, deterministic=True)
            return action

        wall = self._wall0 + time.monotonic() - self._t0
        result = self.evaluator.evaluate(act, int(self.num_timesteps), wall, self.features)
        self.latest = result.kpis
        record(result, self.logger, lambda: self.save_best(self.evaluator.run_dir / BEST_DIR / "model.zip"),
               self.evaluator.run_dir)  # fmt: skip
        return result

    def _on_step(self) -> bool:
        return True
