"""Our side, timed: the env, the vector env (pipelined and in lockstep), workers alone, and TRPO training."""

from __future__ import annotations

import multiprocessing
import os
import queue
import statistics
import time
from pathlib import Path

import numpy as np

from parallel_eplus.bench.config import BenchConfig, _exploring_actions
from parallel_eplus.engine.config import SimulationConfig
from parallel_eplus.engine.simulation import Simulation
from parallel_eplus.envs.env import EnergyPlusEnv
from parallel_eplus.envs.vector_env import EnergyPlusVectorEnv, weather_shares
from parallel_eplus.errors import Interrupts


def _cpu_seconds() -> float:
    """CPU time of this process and its finished children (the EnergyPlus workers, once closed)."""
    t = os.times()
    return t.user + t.system + t.children_user + t.children_system


def env_run(cfg: BenchConfig, workdir: Path) -> dict[str, float]:
    """One `EnergyPlusEnv` episode under the constant action: wall seconds, first observation, steps/s."""
    env = EnergyPlusEnv(
        weather=cfg.weather, run_days=cfg.raw_days, output_dir=workdir, keep_episodes=0, building=cfg.building,
        energyplus_csv=False,  # as training runs it, and as raw_seconds runs EnergyPlus alone
        prepare_next=False,  # one episode: a next one prepared beside it would only take CPU from it
    )  # fmt: skip
    action = np.full(env.action_space.shape, cfg.action, dtype=np.float32)
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
    sim = SimulationConfig(  # EnergyPlus's own CSV off, as training runs it
        weather=cfg.weather, building=cfg.building, run_days=365, output_dir=str(workdir), keep_episodes=0,
        energyplus_csv=False,
    )  # fmt: skip
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
            args=(SimulationConfig(weather=cfg.weather, building=cfg.building, output_dir=str(workdir / f"w{i}"),
                                   keep_episodes=0, energyplus_csv=False), actions[:, i], cfg.workers, results),
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


def training_rate(
    cfg: BenchConfig,
    workdir: Path,
    backend: str = "local",
    run_days: int = 365,
    prepare_next: bool = True,
    fork_episodes: bool = True,
) -> dict[str, float]:
    """Env steps/s inside TRPO learn (paper settings, 16k batch), first observations excluded; `run_days` per episode,
    each worker preparing its next episode while one runs unless `prepare_next` is off.

    backend "ray": the same run through a local Ray, one actor per worker collecting fragments.
    """
    from parallel_eplus.training.callbacks import UpdateTimer
    from parallel_eplus.training.config import TrainConfig
    from parallel_eplus.training.train import train

    tc = TrainConfig(
        workers=cfg.workers, weathers=[cfg.weather], building=cfg.building, timesteps=cfg.train_steps,
        run_days=run_days, prepare_next=prepare_next, fork_episodes=fork_episodes,
        batch_size=-(-cfg.batch_size // cfg.workers) * cfg.workers,  # split evenly across the workers
        run_name="bench", runs_dir=str(workdir / "runs"), tensorboard_dir=str(workdir / "tb"),
        checkpoint_every=10**9, keep_episodes=0, backend=backend, workers_per_actor=1,
    )  # fmt: skip
    timer = UpdateTimer()
    t0 = time.perf_counter()
    train(tc, progress=False, timer=timer)
    seconds = time.perf_counter() - t0
    update = statistics.median(timer.updates) if timer.updates else float("nan")
    # As for the vector env: from the first observations on, so process start-up counts in neither.
    return {"seconds": seconds, "steps_per_s": timer.learn_steps / timer.learn_s, "update_s": update}
