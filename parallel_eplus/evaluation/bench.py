"""`parallel-eplus bench`: our overhead against raw EnergyPlus, measured in one run on this machine.

1. raw: EnergyPlus alone (the agent model, a constant action applied by the EnergyPlus-side callback
   with no pipe exchange), wall seconds from process start to exit;
2. env: the same period and action stepped through `EnergyPlusEnv` (reset + steps, wall seconds);
3. vector env: aggregate steps/s with 1 and N workers, and the scaling efficiency, with the workers
   pipelined (each stepped as soon as it answers, as training steps them) and in lockstep, beside
   the machine's own: N raw runs at once against one, and N workers each stepped alone in a process
   of its own (no shared learner: the ceiling any vector env can reach here), and raw EnergyPlus
   replaying the same actions with no pipes (1 and N processes): what the physics alone costs;
4. training: env steps/s inside TRPO `learn` with N workers, against the vector env's rate and raw's,
   and the floor for a million steps here (raw EnergyPlus's time under those actions plus the updates);
5. time to first observation, peak RSS of one EnergyPlus worker and of the learner.

Random actions in 3 are drawn like an untrained TRPO policy's (N(0, 1) clipped to [-1, 1]), so 3 and
4 ask EnergyPlus for the same kind of work: control changes EnergyPlus's own cost several-fold.
"""

from __future__ import annotations

import itertools
import json
import logging
import multiprocessing
import os
import queue
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from parallel_eplus.buildings.model import AGENT_IDF, STEPS_PER_DAY, control_model
from parallel_eplus.buildings.weather import resolve_weather
from parallel_eplus.engine import native
from parallel_eplus.engine.actions import scale_action
from parallel_eplus.engine.config import SimulationConfig
from parallel_eplus.engine.episode import MODEL_FILE, write_episode_idf
from parallel_eplus.engine.simulation import Simulation
from parallel_eplus.envs.env import EnergyPlusEnv
from parallel_eplus.envs.vector_env import EnergyPlusVectorEnv, weather_shares
from parallel_eplus.errors import Interrupts

log = logging.getLogger(__name__)


@dataclass
class BenchConfig:
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


def _physical(action) -> list[float]:
    """A normalized action in the agent model's physical units, as the env scales it."""
    elements = control_model("temp_fan").actions
    low, high = [e.low for e in elements], [e.high for e in elements]
    return scale_action(action, low, high, tuple(e.name for e in elements))


@dataclass
class RawJob:
    """One raw EnergyPlus run: a model cut to its run period, a weather, and every step's action."""

    idf: Path
    epw: Path
    actions: np.ndarray  # steps x elements, physical units
    model: str = "temp_fan"


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
            sys.executable, "-m", "parallel_eplus.engine.eplus_callback", "--idf", str(job.idf), "--epw", str(job.epw),
            "--output-dir", str(out), "--model", job.model, "--steps", str(len(job.actions)),
            "--initial-action", *(str(e.initial) for e in control_model(job.model).actions),
            "--replay", str(out / "replay.npy"),
            *(["--native", lib] if lib else []),  # the env's own callbacks, minus the pipes
        ])  # fmt: skip
    t0 = time.perf_counter()
    procs = [subprocess.Popen(cmd, stdout=subprocess.PIPE, text=True) for cmd in cmds]
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


def _bench_jobs(cfg: BenchConfig, workdir: Path, replays: np.ndarray) -> list[RawJob]:
    """One job per column of `replays` (steps x copies x actions, normalized) on the bench's weather."""
    workdir.mkdir(parents=True, exist_ok=True)
    idf = workdir / MODEL_FILE  # one model file for all: each run writes its outputs in its own directory
    write_episode_idf(AGENT_IDF, idf, -(-len(replays) // STEPS_PER_DAY))
    epw = resolve_weather(cfg.weather)
    return [RawJob(idf, epw, np.array([_physical(a) for a in replays[:, i]])) for i in range(replays.shape[1])]


def raw_seconds(cfg: BenchConfig, workdir: Path, copies: int = 1) -> float:
    """EnergyPlus alone under the constant action, no pipes; wall seconds, as the env run is timed.

    With `copies` > 1, that many identical runs at once, until the last exits: what the machine itself
    gives N EnergyPlus processes, the ceiling for the vector env's scaling.
    """
    constant = np.full((cfg.raw_days * STEPS_PER_DAY, copies, len(control_model("temp_fan").actions)), cfg.action)
    return _raw_runs(_bench_jobs(cfg, workdir, constant), workdir)[0]


def raw_rate(cfg: BenchConfig, workdir: Path, actions: np.ndarray) -> float:
    """EnergyPlus alone under the vector env's exploring actions (steps x workers x 4), one process per
    worker, all at once, no pipes: aggregate steps/s from the first step on, as the vector env is timed.
    What the physics costs; the vector env and training are measured against it."""
    _, stepping = _raw_runs(_bench_jobs(cfg, workdir, actions), workdir)
    return sum(len(actions) / s for s in stepping)


def replay_run(run_dir: Path, workers: int, workdir: Path, progress: bool = True) -> dict[str, float]:
    """EnergyPlus alone under every action a training run took: its episodes, `workers` at a time, no
    pipes and no learner. What the run's physics cost on this machine, beside what the run took.

    Needs the run's step tables: train with `--keep-episodes` at least its episodes per worker."""
    from tqdm import tqdm

    from parallel_eplus.engine.episode import read_steps

    run_dir = Path(run_dir)
    saved = json.loads((run_dir / "config.json").read_text())
    model = saved.get("model", "temp_fan")
    names = [e.name for e in control_model(model).actions]  # the step table's action columns
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
    jobs = [RawJob(ep / MODEL_FILE, next(ep.glob("*.epw")), read_steps(ep)[names].to_numpy(), model) for ep in in_order]
    steps = sum(len(j.actions) for j in jobs)
    wall = 0.0
    with tqdm(total=steps, unit="step", desc="replay", disable=not progress) as bar:
        for k in range(0, len(jobs), workers):  # the run's workers' k-th episodes side by side, as they ran
            batch = jobs[k : k + workers]
            seconds, _ = _raw_runs(batch, workdir / f"round{k}")
            wall += seconds
            bar.update(sum(len(j.actions) for j in batch))
    return {"episodes": len(jobs), "steps": steps, "raw_wall_s": wall, "raw_steps_per_s": steps / wall}


def _cpu_seconds() -> float:
    """CPU time of this process and its finished children (the EnergyPlus workers, once closed)."""
    t = os.times()
    return t.user + t.system + t.children_user + t.children_system


def env_run(cfg: BenchConfig, workdir: Path) -> dict[str, float]:
    env = EnergyPlusEnv(weather=cfg.weather, run_days=cfg.raw_days, output_dir=workdir, keep_episodes=0)
    action = np.full(4, cfg.action, dtype=np.float32)
    try:
        t0 = time.perf_counter()
        env.reset()
        t_first = time.perf_counter() - t0
        steps, terminated = 0, False
        while not terminated:
            _, _, terminated, _, _ = env.step(action)
            steps += 1
        total = time.perf_counter() - t0
    finally:
        env.close()
    return {"seconds": total, "first_obs_s": t_first, "steps": steps, "steps_per_s": steps / (total - t_first)}


def _exploring_actions(cfg: BenchConfig, workers: int) -> np.ndarray:
    """(steps, workers, 4) actions drawn like an untrained policy's, the same for every measurement."""
    steps = cfg.vector_steps or cfg.train_steps // cfg.workers
    rng = np.random.default_rng(0)
    return np.clip(rng.normal(size=(steps, workers, 4)), -1, 1).astype(np.float32)


def _step_pipelined(venv: EnergyPlusVectorEnv, actions: np.ndarray) -> None:
    """Each worker through its own column of `actions`, handed its next action as soon as it answers."""
    steps_done = [0] * venv.num_envs
    for i in range(venv.num_envs):
        venv.send_one(i, actions[0, i])
    pending = set(range(venv.num_envs))
    while pending:
        for i in venv.ready(pending):
            if venv.receive_one(i) is None:  # a new episode starting up
                continue
            steps_done[i] += 1
            if steps_done[i] < len(actions):
                venv.send_one(i, actions[steps_done[i], i])
            else:
                pending.discard(i)


def vector_rate(cfg: BenchConfig, workers: int, workdir: Path, pipelined: bool = True) -> dict[str, float]:
    """Aggregate env steps/s of the vector env over `vector_steps` per worker, after the first observations,
    and the cores it kept busy (CPU seconds of learner and workers, start-up included, per wall second).

    `pipelined`: each worker stepped as soon as it answers (as training steps them); else in lockstep."""
    sim = SimulationConfig(weather=cfg.weather, run_days=365, output_dir=str(workdir), keep_episodes=0)
    actions = _exploring_actions(cfg, workers)
    cpu0, wall0 = _cpu_seconds(), time.perf_counter()
    venv = EnergyPlusVectorEnv(sim, weather_shares([cfg.weather], workers))
    try:
        venv.start_all(range(workers))
        t0 = time.perf_counter()
        if pipelined and workers > 1:
            _step_pipelined(venv, actions)
        else:
            for a in actions:
                venv.step_lists(a)
        rate = workers * len(actions) / (time.perf_counter() - t0)
    finally:
        venv.close()
    return {"steps_per_s": rate, "cores_busy": (_cpu_seconds() - cpu0) / (time.perf_counter() - wall0)}


def _step_alone(sim_cfg: SimulationConfig, actions: np.ndarray, siblings: int, results) -> None:
    """One worker stepped by a process of its own; puts its steps/s (or its error) on `results`."""
    sim = None
    try:
        with Interrupts():  # the parent's terminate(), or Ctrl-C, still closes EnergyPlus and the pipes
            sim = Simulation(sim_cfg, siblings=siblings)
            sim.start()
            t0 = time.perf_counter()
            for a in actions:
                sim.send(a)
                sim.receive()
            results.put(len(actions) / (time.perf_counter() - t0))
    except KeyboardInterrupt:
        pass  # the parent stops us; it reports the interruption
    except Exception as e:  # noqa: BLE001 - reported to the parent, which raises it
        results.put(f"{type(e).__name__}: {e}")
    finally:
        if sim is not None:
            sim.close()


def independent_rate(cfg: BenchConfig, workdir: Path) -> float:
    """Aggregate steps/s of N workers each stepped alone in a process of its own, all at once: the vector
    env's actions without its lockstep (every step waits for the slowest worker) or a learner process
    shared by all. What this machine gives N workers: the ceiling of the vector env's scaling."""
    actions = _exploring_actions(cfg, cfg.workers)
    ctx = multiprocessing.get_context("spawn")
    results = ctx.Queue()
    procs = [
        ctx.Process(
            target=_step_alone,
            args=(SimulationConfig(weather=cfg.weather, output_dir=str(workdir / f"w{i}"), keep_episodes=0),
                  actions[:, i], cfg.workers, results),
        )
        for i in range(cfg.workers)
    ]  # fmt: skip
    for p in procs:
        p.start()
    rates: list[float] = []
    try:
        while len(rates) < len(procs):
            try:
                got = results.get(timeout=1.0)
            except queue.Empty:
                if any(p.exitcode not in (None, 0) for p in procs):
                    raise RuntimeError("a worker process of the independent-loop benchmark died") from None
                continue
            if isinstance(got, str):
                raise RuntimeError(f"independent-loop benchmark: {got}")
            rates.append(got)
    finally:
        for p in procs:
            if p.is_alive() and len(rates) < len(procs):
                p.terminate()
            p.join()
    return sum(rates)


def training_rate(cfg: BenchConfig, workdir: Path) -> dict[str, float]:
    """Env steps/s inside TRPO learn (paper settings, 16k batch), first observations excluded."""
    from parallel_eplus.training.callbacks import UpdateTimer
    from parallel_eplus.training.config import TrainConfig
    from parallel_eplus.training.train import train

    tc = TrainConfig(
        workers=cfg.workers, weathers=[cfg.weather], timesteps=cfg.train_steps,
        batch_size=-(-cfg.batch_size // cfg.workers) * cfg.workers,  # split evenly across the workers
        run_name="bench", runs_dir=str(workdir / "runs"), tensorboard_dir=str(workdir / "tb"),
        checkpoint_every=10**9, keep_episodes=0,
    )  # fmt: skip
    timer = UpdateTimer()
    t0 = time.perf_counter()
    train(tc, progress=False, timer=timer)
    seconds = time.perf_counter() - t0
    update = statistics.median(timer.updates) if timer.updates else float("nan")
    # As for the vector env: from the first observations on, so process start-up counts in neither.
    return {"seconds": seconds, "steps_per_s": timer.learn_steps / timer.learn_s, "update_s": update}


def run(cfg: BenchConfig, out: Path | None = None) -> dict:
    results: dict = {"config": asdict(cfg), "machine": {"cores": os.cpu_count()}}
    with tempfile.TemporaryDirectory(prefix="parallel-eplus-bench-") as tmp:
        tmp = Path(tmp)
        # Back to back within each repeat, and ratios taken per repeat: this machine's speed drifts by
        # 10-20 % from one minute to the next, which medians of separate series would not cancel.
        raw, raw_n, envs = [], [], []
        for i in range(cfg.repeats):
            raw.append(raw_seconds(cfg, tmp / f"raw{i}"))
            envs.append(env_run(cfg, tmp / f"env{i}"))
            # The machine's own ceiling on scaling: N raw runs at once against one alone.
            raw_n.append(raw_seconds(cfg, tmp / f"rawN{i}", copies=cfg.workers))
        worker_rss_mb = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024
        results["raw_s"] = statistics.median(raw)
        results["raw_n_s"] = statistics.median(raw_n)
        results["raw_scaling"] = statistics.median(r / n for r, n in zip(raw, raw_n, strict=True))
        results["env_s"] = statistics.median(e["seconds"] for e in envs)
        results["env_steps_per_s"] = statistics.median(e["steps_per_s"] for e in envs)
        results["env_over_raw"] = statistics.median(e["seconds"] / r for e, r in zip(envs, raw, strict=True))
        results["first_obs_s"] = statistics.median(e["first_obs_s"] for e in envs)
        one, many, lockstep, alone, phys_1, phys_n = [], [], [], [], [], []
        for i in range(cfg.repeats):
            # What the physics costs under the same exploring actions, beside what we make of it.
            phys_1.append(raw_rate(cfg, tmp / f"p1_{i}", _exploring_actions(cfg, 1)))
            phys_n.append(raw_rate(cfg, tmp / f"pN_{i}", _exploring_actions(cfg, cfg.workers)))
            one.append(vector_rate(cfg, 1, tmp / f"v1_{i}"))
            many.append(vector_rate(cfg, cfg.workers, tmp / f"vN_{i}"))
            lockstep.append(vector_rate(cfg, cfg.workers, tmp / f"vL_{i}", pipelined=False))
            alone.append(independent_rate(cfg, tmp / f"alone_{i}"))
        results["raw_exploring_1_steps_per_s"] = statistics.median(phys_1)
        results["raw_exploring_n_steps_per_s"] = statistics.median(phys_n)
        results["vector_1_over_raw"] = statistics.median(r["steps_per_s"] / p for r, p in zip(one, phys_1, strict=True))
        results["vector_n_over_raw"] = statistics.median(
            r["steps_per_s"] / p for r, p in zip(many, phys_n, strict=True)
        )
        results["vector_1_steps_per_s"] = statistics.median(r["steps_per_s"] for r in one)
        results["vector_n_steps_per_s"] = statistics.median(r["steps_per_s"] for r in many)
        results["vector_1_cores_busy"] = statistics.median(r["cores_busy"] for r in one)
        results["vector_n_cores_busy"] = statistics.median(r["cores_busy"] for r in many)
        results["scaling_efficiency"] = results["vector_n_steps_per_s"] / (
            cfg.workers * results["vector_1_steps_per_s"]
        )
        results["lockstep_n_steps_per_s"] = statistics.median(r["steps_per_s"] for r in lockstep)
        results["lockstep_scaling"] = results["lockstep_n_steps_per_s"] / (
            cfg.workers * results["vector_1_steps_per_s"]
        )
        results["independent_n_steps_per_s"] = statistics.median(alone)
        results["independent_scaling"] = results["independent_n_steps_per_s"] / (
            cfg.workers * results["vector_1_steps_per_s"]
        )
        tr = training_rate(cfg, tmp / "train")
        results["train_steps_per_s"] = tr["steps_per_s"]
        results["train_over_vector"] = tr["steps_per_s"] / results["vector_n_steps_per_s"]
        results["update_s"] = tr["update_s"]
        results["million_steps_minutes"] = 1e6 / tr["steps_per_s"] / 60
        results["train_over_raw"] = tr["steps_per_s"] / results["raw_exploring_n_steps_per_s"]
        # The floor for 1M steps here: EnergyPlus's own time under these actions, plus the updates.
        results["million_steps_floor_minutes"] = (
            1e6 / results["raw_exploring_n_steps_per_s"] + 1e6 / cfg.batch_size * tr["update_s"]
        ) / 60
        results["worker_peak_rss_mb"] = worker_rss_mb
        results["learner_peak_rss_mb"] = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    if out is not None:
        out.parent.mkdir(parents=True, exist_ok=True)
        out.write_text(json.dumps(results, indent=2))
    return results


def format_table(r: dict) -> str:
    c = r["config"]
    n = c["workers"]
    rows = [
        ("raw EnergyPlus, constant action", f"{r['raw_s']:.2f} s for {c['raw_days']} days", ""),
        ("EnergyPlusEnv, same action", f"{r['env_s']:.2f} s ({r['env_steps_per_s']:.0f} steps/s)",
         f"env/raw {r['env_over_raw']:.2f} (target <= 1.25)"),
        (f"raw EnergyPlus, {n} runs at once", f"{r['raw_n_s']:.2f} s",
         f"the machine's own scaling {r['raw_scaling']:.2f}"),
        ("raw EnergyPlus, exploring actions, 1 run", f"{r['raw_exploring_1_steps_per_s']:.0f} steps/s",
         "the physics alone, start-up excluded"),
        (f"raw EnergyPlus, exploring actions, {n} at once", f"{r['raw_exploring_n_steps_per_s']:.0f} steps/s", ""),
        ("vector env, 1 worker", f"{r['vector_1_steps_per_s']:.0f} steps/s",
         f"{r['vector_1_over_raw']:.2f} of raw; {r['vector_1_cores_busy']:.2f} cores busy"),
        (f"vector env, {n} workers, pipelined", f"{r['vector_n_steps_per_s']:.0f} steps/s",
         f"scaling {r['scaling_efficiency']:.2f} (target >= 0.90); {r['vector_n_over_raw']:.2f} of raw"),
        (f"vector env, {n} workers, lockstep", f"{r['lockstep_n_steps_per_s']:.0f} steps/s",
         f"scaling {r['lockstep_scaling']:.2f}"),
        (f"{n} workers stepped alone, at once", f"{r['independent_n_steps_per_s']:.0f} steps/s",
         f"scaling {r['independent_scaling']:.2f}: the ceiling without lockstep or learner"),
        (f"TRPO learn, {n} workers", f"{r['train_steps_per_s']:.0f} steps/s",
         f"train/vector {r['train_over_vector']:.2f} (target >= 0.75); {r['train_over_raw']:.2f} of raw"),
        ("TRPO update of one 16k batch", f"{r['update_s']:.2f} s", ""),
        ("1M TRPO steps", f"{r['million_steps_minutes']:.1f} min",
         f"target <= 15 min; EnergyPlus's own time and the updates: {r['million_steps_floor_minutes']:.1f} min"),
        ("time to first observation", f"{r['first_obs_s']:.2f} s", "target <= 2 s"),
        ("peak RSS: EnergyPlus worker / learner", f"{r['worker_peak_rss_mb']:.0f} / {r['learner_peak_rss_mb']:.0f} MB",
         "worker target <= 300 MB"),
    ]  # fmt: skip
    width = max(len(a) for a, _, _ in rows)
    return "\n".join(f"{a:<{width}}  {b:<28} {t}" for a, b, t in rows)
