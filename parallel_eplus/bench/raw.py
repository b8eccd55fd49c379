"""Raw EnergyPlus: the env's own simulation minus the pipes, the yardstick every ratio is taken against."""

from __future__ import annotations

import itertools
import json
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from parallel_eplus.bench.config import BenchConfig, bench_building
from parallel_eplus.buildings.building import load_building
from parallel_eplus.buildings.datacenter import control_model
from parallel_eplus.buildings.idf.prepare import prepare_idf
from parallel_eplus.buildings.idf.takeover import taken_setpoints
from parallel_eplus.buildings.weather.files import resolve_weather
from parallel_eplus.engine.actions import scale_action
from parallel_eplus.engine.episode import MODEL_FILE
from parallel_eplus.engine.eplus_side import native


def _physical(action, building: str | None = None) -> list[float]:
    """A normalized action in the agent model's physical units, as the env scales it (None: the data center's)."""
    elements = load_building(building).actions
    low, high = [e.low for e in elements], [e.high for e in elements]
    return scale_action(action, low, high, tuple(e.name for e in elements))


@dataclass
class RawJob:
    """One raw EnergyPlus run: a model cut to its run period, a weather, and every step's action."""

    idf: Path
    epw: Path
    actions: np.ndarray  # steps x elements, physical units
    model: str = "temp_fan"
    building: str | None = None  # a spec: its actions instead of the data center's `model`

    def elements(self):
        return load_building(self.building).actions if self.building else control_model(self.model).actions

    def args(self) -> list[str]:
        """What the EnergyPlus side needs to know the actions: the data center's variant or the spec."""
        building = ["--building", str(load_building(self.building).spec.path)] if self.building else []
        return ["--model", self.model, *building, "--initial-action", *(str(e.initial) for e in self.elements())]


def _raw_runs(jobs: list[RawJob], workdir: Path) -> tuple[float, list[float]]:
    """The jobs' EnergyPlus processes all at once, each in its own directory, until the last exits:
    (wall seconds, each run's stepping seconds from its first step on).

    Each run is the env's simulation without the pipes: warmup under the model's initial action, then
    step k's action applied where the env would apply it (tests/test_bench.py checks they agree)."""
    lib = native.bridge_library()
    cmds = []
    for i, job in enumerate(jobs):
        out = workdir / f"copy{i}"
        out.mkdir(parents=True, exist_ok=True)
        np.save(out / "replay.npy", job.actions)
        cmds.append([
            sys.executable, "-m", "parallel_eplus.engine.eplus_side.callback",
            "--idf", str(job.idf), "--epw", str(job.epw),
            "--output-dir", str(out), "--steps", str(len(job.actions)), *job.args(),
            "--replay", str(out / "replay.npy"),
            *(["--native", lib] if lib else []),  # the env's own callbacks, minus the pipes
        ])  # fmt: skip
    t0 = time.perf_counter()
    # Each in a session of its own, as training starts its workers (episodes/process.py): with the kernel's autogroups
    # a session is what the scheduler shares the CPU between, so on a shared machine both get the same weight.
    procs = [subprocess.Popen(cmd, stdout=subprocess.PIPE, text=True, start_new_session=True) for cmd in cmds]
    try:
        outputs = [proc.communicate()[0] for proc in procs]
    finally:  # Ctrl-C or a failed run: leave no EnergyPlus behind
        for proc in procs:
            if proc.poll() is None:
                proc.kill()
                proc.wait()
    seconds = time.perf_counter() - t0
    for proc, cmd in zip(procs, cmds, strict=True):
        if proc.returncode != 0:
            raise subprocess.CalledProcessError(proc.returncode, cmd)
    stepping = [float(ln.split()[1]) for out in outputs for ln in out.splitlines() if ln.startswith("stepping_s")]
    return seconds, stepping


def _bench_jobs(cfg: BenchConfig, workdir: Path, replays: np.ndarray, energyplus_csv: bool) -> list[RawJob]:
    """One job per column of `replays` (steps x copies x actions, normalized) on the bench's weather, with
    EnergyPlus's own CSV off, as training runs EnergyPlus (on: a test compares the files)."""
    workdir.mkdir(parents=True, exist_ok=True)
    building = bench_building(cfg)
    idf = workdir / MODEL_FILE  # one model file for all: each run writes its outputs in its own directory
    control = building.control()
    days = -(-len(replays) // building.steps_per_day)
    prepare_idf(
        control.idf,
        idf,
        days,
        energyplus_csv,
        takeover=taken_setpoints(control.actions),
        ventilation=building.spec.demand_ventilation,
    )
    epw = building.spec.weathers.get(cfg.weather) or resolve_weather(cfg.weather)
    model = building.spec.name if cfg.building else "temp_fan"
    return [
        RawJob(idf, epw, np.array([_physical(a, cfg.building) for a in replays[:, i]]), model, cfg.building)
        for i in range(replays.shape[1])
    ]


def raw_seconds(cfg: BenchConfig, workdir: Path, copies: int = 1) -> float:
    """EnergyPlus alone under the constant action, no pipes; wall seconds, as the env run is timed.

    With `copies` > 1, that many identical runs at once, until the last exits: what the machine itself
    gives N EnergyPlus processes, the ceiling for the vector env's scaling.
    """
    building = bench_building(cfg)
    constant = np.full((cfg.raw_days * building.steps_per_day, copies, len(building.actions)), cfg.action)
    return _raw_runs(_bench_jobs(cfg, workdir, constant, energyplus_csv=False), workdir)[0]


def raw_rate(cfg: BenchConfig, workdir: Path, actions: np.ndarray, energyplus_csv: bool = False) -> float:
    """EnergyPlus alone under the vector env's exploring actions (steps x workers x actions), one process per
    worker, all at once, no pipes: aggregate steps/s from the first step on, as the vector env is timed.
    What the physics costs; the vector env and training are measured against it."""
    _, stepping = _raw_runs(_bench_jobs(cfg, workdir, actions, energyplus_csv), workdir)
    return sum(len(actions) / s for s in stepping)


def replay_run(run_dir: Path, workers: int, workdir: Path, progress: bool = True) -> dict[str, float]:
    """EnergyPlus alone under every action a training run took: its episodes, `workers` at a time, no
    pipes and no learner. What the run's physics cost on this machine, beside what the run took.

    Needs the run's step tables: train with `--keep-episodes` at least its episodes per worker."""
    from tqdm import tqdm

    from parallel_eplus.engine.episode import read_steps

    run_dir = Path(run_dir)
    saved = json.loads((run_dir / "config.json").read_text())
    model, building = saved.get("model", "temp_fan"), saved.get("building")
    elements = load_building(building).actions if building else control_model(model).actions
    names = [e.name for e in elements]  # the step table's action columns
    columns = sorted((run_dir / "episodes").glob("worker-*"))
    episodes = [sorted(d for d in w.glob("episode-*") if (d / "steps.parquet").is_file()) for w in columns]
    summaries = sum(len(list(w.glob("episode-*"))) for w in columns)
    found = sum(map(len, episodes))
    if found < summaries:
        raise ValueError(
            f"{run_dir}: {summaries - found} of {summaries} episodes have no step table left; "
            "train with --keep-episodes at least as large as the episodes per worker to replay a run"
        )
    in_order = [ep for column in itertools.zip_longest(*episodes) for ep in column if ep is not None]
    jobs = [
        RawJob(ep / MODEL_FILE, next(ep.glob("*.epw")), read_steps(ep)[names].to_numpy(), model, building)
        for ep in in_order
    ]
    steps = sum(len(j.actions) for j in jobs)
    wall = 0.0
    with tqdm(total=steps, unit="step", desc="replay", disable=not progress) as bar:
        for k in range(0, len(jobs), workers):  # the run's workers' k-th episodes side by side, as they ran
            batch = jobs[k : k + workers]
            seconds, _ = _raw_runs(batch, workdir / f"round{k}")
            wall += seconds
            bar.update(sum(len(j.actions) for j in batch))
    return {"episodes": len(jobs), "steps": steps, "raw_wall_s": wall, "raw_steps_per_s": steps / wall}
