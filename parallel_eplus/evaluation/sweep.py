"""The evaluation sweep: controllers x weathers, one full episode each, run in parallel.

Controllers (controllers.py): the built-in one (the baseline model, no agent), trained policies (deterministic, with
their saved observation statistics) and the rule-based controller. Every episode's reward comes from
the same reward function on the same signals, so rewards compare across controllers.
"""

from __future__ import annotations

import logging
from collections import deque
from pathlib import Path

import pandas as pd
from tqdm import tqdm

from parallel_eplus.buildings.building import Building, load_building
from parallel_eplus.buildings.scoring.reward import RewardConfig
from parallel_eplus.buildings.weather.files import parse_weathers, weather_label
from parallel_eplus.engine.config import SimulationConfig
from parallel_eplus.engine.simulation import Simulation, wait_any
from parallel_eplus.errors import EnergyPlusError
from parallel_eplus.evaluation.controllers import (
    ORACLE_KIND,
    Controller,
    failure_row,
    slug,
    unique_labels,
)

log = logging.getLogger(__name__)


def run_sweep(
    controllers: list[Controller],
    weathers: list[str],
    run_days: int,
    workers: int,
    out_dir: Path,
    reward: RewardConfig | None = None,
    progress: bool = True,
    building: str | Path | Building | None = None,
    backend: str = "local",
    ray_address: str | None = None,
    keep_going: bool = False,
    periods: dict | None = None,
    extra_outputs: tuple[tuple[str, str], ...] = (),
    weather_noise: str | None = None,
    noisy_years: int = 1,
    resume: bool = False,
) -> pd.DataFrame:
    """One episode per (controller, weather), up to `workers` at once; returns results.csv's table.

    `periods`: weather -> a test period (evaluation/scenarios.py) run instead of `run_days` from January 1;
    `extra_outputs`: (key, variable) pairs EnergyPlus reports every step in each episode's eplusout.csv.

    `weather_noise` (buildings/weather/noise.py): instead, `noisy_years` episodes per (controller, weather), year k
    the weather perturbed with seed k for every controller; each year is a `run` of the row's controller, so the
    results give the mean over years and its interval (seeds.py).

    `backend` "ray": each episode is a Ray task (ray_sweep.py), on `ray_address`'s cluster or a local Ray.

    `building`: a spec (a path, a built-in name, or the `Building` the command resolved; checked first); its
    "baseline" is its model's own controls (`baseline_idf`). None: the data center.

    `keep_going`: an episode whose EnergyPlus fails (a model's own controls can fail on a weather) is left out
    and the others run on; the table's `attrs["failures"]` lists what failed, why and where (`failure_row`).
    Otherwise the first failure stops the sweep, as any caller averaging over the weathers needs.

    `resume`: the jobs whose episode a previous sweep into `out_dir` finished are not run again (resume.py)."""
    swept = load_building(building)  # resolved once (by the command, or here): every job reads this object
    known = None
    if swept.named:
        from parallel_eplus.buildings.check.names import check_building

        check_building(swept)
        known = swept.spec.weathers
    for c in controllers:  # a policy acts only in the building it was trained on, or a variant of it
        trained = load_building(c.building) if c.kind in ("policy", "http", "planner") else swept
        if trained.spec.path == swept.spec.path:
            continue
        if trained.interface() != swept.interface():
            raise ValueError(
                f"{c.path or c.url} was trained on building {c.building or 'datacenter-2zone (default)'}, "
                f"not {swept.spec.path if swept.named else 'datacenter-2zone (default)'}: pass --building accordingly"
            )
        log.warning("%s was trained on %s and acts in %s, a variant with the same observations and actions: what "
                    "it learned of the building may not hold there", c.path or c.url, trained.spec.path,
                    swept.spec.path if swept.named else None)  # fmt: skip
    weathers = parse_weathers(",".join(weathers), known)  # fail before anything runs
    if backend == "ray" and any(c.kind == ORACLE_KIND for c in controllers):
        raise ValueError("--oracle forks the running episode on this machine: run it with --backend local")
    for c in controllers:  # a rule-based controller the building cannot take fails here, not mid-sweep
        if c.kind == "rbc":
            c.make(swept)
    controllers = unique_labels(controllers)
    if weather_noise is not None:
        from parallel_eplus.buildings.weather.noise import parse_noise

        parse_noise(weather_noise)  # a malformed option fails before anything runs
        if noisy_years < 1:
            raise ValueError("--noisy-years must be at least 1")
    years = range(noisy_years) if weather_noise is not None else [None]
    jobs = [
        (c, _job_config(c, w, swept, run_days, reward, out_dir, weather_noise, k))
        for c in controllers for w in weathers for k in years
    ]  # fmt: skip
    for _, cfg in jobs:
        cfg.extra_outputs = extra_outputs
        p = (periods or {}).get(weather_label(cfg.weather))
        if p is not None:
            cfg.run_days, cfg.start_day, cfg.start_weekday, cfg.warmup_days = (
                p.run_days, p.start_day, p.weekday, p.warmup_days
            )  # fmt: skip
    finished: list[dict] = []
    if resume:
        from parallel_eplus.evaluation.resume import split_finished

        finished, jobs = split_finished(jobs)
    steps_per_day = swept.steps_per_day
    total_steps = sum(cfg.run_days for _, cfg in jobs) * steps_per_day
    band = _band_columns(swept)
    bar = tqdm(total=total_steps, unit="step", desc="evaluate", disable=not progress, smoothing=0.05)
    try:
        if not jobs:  # every episode finished before (`resume`)
            rows, failures = [], []
        elif backend == "ray":
            from parallel_eplus.evaluation import ray_sweep

            # each EnergyPlus step has its own deadline; this bounds the wait for any next episode to end. A planner
            # decides in 10-30 ms a step on a quiet core: on a loaded machine a planner-year outlasted 0.05 s a step
            per_step = 0.25 if any(c.kind == "planner" for c, _ in jobs) else 0.05
            deadline_s = 600.0 + run_days * steps_per_day * per_step
            rows, failures = ray_sweep.run_jobs(jobs, workers, ray_address, bar, deadline_s, keep_going)
        else:
            rows, failures = run_local(jobs, workers, bar, keep_going, swept)
    finally:
        bar.close()
    rows = [{**row, **band} for row in finished + rows]  # a spec's band, beside its "% in band"
    if weather_noise is not None:  # each noisy year is one of the controller's runs (seeds.py's intervals)
        rows = [{**row, "run": f"{row.get('run') or ''} year {row['weather_seed']}".strip()} for row in rows]
    order = {c.label: i for i, c in enumerate(controllers)}
    worder = {weather_label(w): i for i, w in enumerate(weathers)}
    df = pd.DataFrame(rows)
    if rows:
        df = df.sort_values(by=["controller", "weather"], key=lambda s: s.map({**order, **worder}))
    df = df.reset_index(drop=True)
    df.attrs["failures"] = failures
    return df


def _job_config(
    controller: Controller, weather: str, building: str | Building | None, run_days: int, reward: RewardConfig | None,
    out_dir: Path, weather_noise: str | None = None, year: int | None = None,
) -> SimulationConfig:  # fmt: skip
    """`building`: as the config names it (a spec's path; None: the data center), or its `Building` resolved."""
    folder = out_dir / "episodes" / slug(controller.label) / (controller.run or "") / weather_label(weather)
    (residual_scale, residual_space), relinquish = controller.residual(building), controller.relinquishes(building)
    if isinstance(building, Building):
        building = str(building.spec.path) if building.named else None
    return SimulationConfig(
        weather=weather, model=controller.model, building=building, run_days=run_days,
        reward=reward or RewardConfig(),
        time_features=controller.time_features, schedule_features=controller.schedule_features,
        residual_scale=residual_scale, residual_space=residual_space,
        rbc_target_c=controller.rbc_target_c, relinquish=relinquish,
        output_dir=str(folder if year is None else folder / f"year-{year}"),
        forecast_hours=controller.forecast_hours, forecast_error=controller.forecast_error,
        weather_noise=weather_noise, seed=year or 0, fixed_seed=year is not None,
        branching=controller.kind == ORACLE_KIND, native_bridge=controller.kind != ORACLE_KIND,
    )  # fmt: skip


def run_local(
    jobs: list[tuple[Controller, SimulationConfig]],
    workers: int,
    bar,
    keep_going: bool = False,
    building: Building | None = None,
) -> tuple[list[dict], list[dict]]:
    """The jobs as EnergyPlus processes of this machine, up to `workers` at once: (rows, failures). `building`: the
    jobs' building as the command resolved it (None: each job's resolved from its config)."""
    queue = deque(jobs)
    rows: list[dict] = []
    failures: list[dict] = []
    active: list[dict] = []

    def failed(job: dict, error: EnergyPlusError) -> None:
        if not keep_going:
            raise error
        failures.append(failure_row(job["controller"], job["cfg"], error))
        active.remove(job)
        _close(job)

    try:
        while queue or active:
            started = []
            while queue and len(active) < workers:
                controller, cfg = queue.popleft()
                sim = Simulation(cfg, name=controller.label, siblings=workers, building=building)
                job = {"controller": controller, "cfg": cfg, "sim": sim, "act": controller.make(sim.building)}
                active.append(job)  # (closed below whatever fails from here)
                if controller.kind == ORACLE_KIND:
                    job["act"].bind(sim)  # it forks this episode's process
                try:
                    sim.launch()
                    started.append(job)
                except EnergyPlusError as e:
                    failed(job, e)
            for job in started:
                try:
                    obs, info = job["sim"].first_observation()
                    job["sim"].send(job["act"](obs, info))
                except EnergyPlusError as e:
                    failed(job, e)
            # Pipelined: each job gets its next action as soon as it answers, so a cheap episode (the
            # built-in controller's) runs ahead of a costly one instead of at its pace.
            finished, broken = [], []
            for k in wait_any([job["sim"].process for job in active], range(len(active))):
                job = active[k]
                try:
                    obs, _, terminated, info = job["sim"].receive()
                    bar.update(1)
                    if terminated:
                        job["info"] = info
                        finished.append(job)
                    else:
                        job["sim"].send(job["act"](obs, info))
                except EnergyPlusError as e:
                    broken.append((job, e))
            for job, e in broken:  # after the loop: `wait_any`'s indices are into `active` as it was
                failed(job, e)
            for job in finished:
                active.remove(job)
                summary = job["info"]["episode_summary"]
                c = job["controller"]
                rows.append({"controller": c.label, "run": c.run, **summary, "episode_dir": job["info"]["episode_dir"]})
                _close(job)
                bar.set_postfix(done=len(rows), last=f"{job['controller'].label} {summary['weather']}")
    finally:
        for job in active:
            _close(job)
    return rows, failures


def _close(job: dict) -> None:
    """A job's simulation, then its controller where it holds something (a served controller's connection: closing
    it logs its POST /act round trips)."""
    job["sim"].close()
    if callable(close := getattr(job["act"], "close", None)):
        close()


def _band_columns(b: Building) -> dict:
    """A spec's one band beside its "% in band"; none where each zone has its own bounds (thermostat, per zone)."""
    if not b.named or b.spec.reward.thermostat or b.spec.reward.zone_bands:
        return {}
    return dict(zip(("band_low_c", "band_high_c"), b.band, strict=True))
