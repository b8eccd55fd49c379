"""What `--algorithm mbpo`'s ensemble starts from and keeps: a planner run's model and data, the building's own
controls recorded, or the run's own saved state (runs/<name>/mbpo/: the ensemble, its transitions, the start
states)."""

from __future__ import annotations

import datetime as dt
from pathlib import Path

import numpy as np

from parallel_eplus.buildings.building import load_building
from parallel_eplus.learning.model_based.control.mpc import MPC, PLANNER_FILE
from parallel_eplus.learning.model_based.model.dataset import Transitions
from parallel_eplus.learning.model_based.students.through_model import Starts

STATE_DIR = "mbpo"  # runs/<name>/mbpo/
TRANSITIONS, STARTS = "transitions.npz", "starts.npz"


def save_state(folder: Path, mpc: MPC, data: Transitions, starts: Starts) -> None:
    from parallel_eplus import io

    folder.mkdir(parents=True, exist_ok=True)
    mpc.save(folder / PLANNER_FILE)
    with io.atomic_path(folder / TRANSITIONS) as tmp, open(tmp, "wb") as f:  # a file: savez adds no suffix
        data.save(f)
    with io.atomic_path(folder / STARTS) as tmp, open(tmp, "wb") as f:
        np.savez_compressed(
            f,
            obs=np.asarray(starts.obs),
            prev=np.asarray(starts.prev),
            times=np.asarray(starts.times, "datetime64[s]"),
            weathers=np.asarray(starts.weathers),
        )


def record_own_controls(cfg, mpc: MPC, data: Transitions, starts: Starts, progress: bool) -> None:
    """`record_days` of the building's own controls on the training weathers, as the policy observes them: their
    transitions into the ensemble's data, their states into the start states."""
    import shutil

    from parallel_eplus.learning.imitation import record_baseline
    from parallel_eplus.learning.model_based.model.sources import add_baseline

    folder = cfg.run_dir / "baseline-record"
    days = cfg.mbpo.record_days or cfg.run_days
    demos = record_baseline(cfg.building, cfg.weathers, days, cfg.workers, folder,
                            (cfg.time_features, cfg.schedule_features), progress)  # fmt: skip
    comfort = load_building(cfg.building).comfort
    first = int(data.array("episode").max()) + 1 if len(data) else 0
    add_baseline(data, demos, mpc, lambda t, v: comfort.always or comfort.applies(t, v), first)
    shutil.rmtree(folder, ignore_errors=True)
    labels = np.array(demos.weathers)
    for weather in dict.fromkeys(demos.weathers):
        rows = np.flatnonzero(labels == weather)
        for r0, r in zip(rows[:-1], rows[1:], strict=True):  # each state after the first, and the action before it
            starts.add(demos.observations[r], demos.actions[r0], demos.times[r], weather)


def load_state(folder: Path, workers: int, seed: int) -> tuple[MPC, Transitions, Starts]:
    """The ensemble, its data and the start states a run saved (or a planner run's: `from_planner_run`)."""
    mpc = MPC.load(folder / PLANNER_FILE, workers, seed)
    data = Transitions.load(folder / TRANSITIONS, mpc.layout)
    with np.load(folder / STARTS) as z:
        times = [t.astype(dt.datetime) for t in z["times"].astype("datetime64[s]")]
        starts = Starts.of(z["obs"], z["prev"], times, [str(w) for w in z["weathers"]])
    return mpc, data, starts


def from_planner_run(run: Path, workers: int, seed: int) -> tuple[MPC, Transitions, Starts]:
    """`--init-from runs/<mpc-run>` (or its planner/ or best/planner/ folder): its ensemble, and where the run kept
    them, every transition it saw (transitions.npz, or its newest checkpoint) and the states of the planner's steps
    (its newest checkpoint) as the first start states. A committed planner (the ensemble alone) starts with
    neither: the run's own steps supply both."""
    from parallel_eplus.learning.model_based.control.checkpoint import Checkpoint, newest_checkpoint

    folder = run if (run / PLANNER_FILE).is_file() else run / "planner"
    if not (folder / PLANNER_FILE).is_file():
        raise FileNotFoundError(f"--init-from {run}: no planner ({folder / PLANNER_FILE}); give a `train "
                                "--algorithm mpc` run's folder")  # fmt: skip
    run = run if folder != run else (run.parent.parent if run.parent.name == "best" else run.parent)
    mpc = MPC.load(folder / PLANNER_FILE, workers, seed)
    data, starts = Transitions(mpc.layout), Starts()
    try:
        _, data, policy = Checkpoint.load(newest_checkpoint(run), mpc.layout)
    except FileNotFoundError:
        policy = None
    if (run / TRANSITIONS).is_file():  # every transition of a finished run
        data = Transitions.load(run / TRANSITIONS, mpc.layout)
    if policy is not None and len(policy) == 5:
        obs, _, prev, times, weathers = policy
        times = [t.astype(dt.datetime) for t in np.asarray(times).astype("datetime64[s]")]
        starts = Starts.of(obs[len(obs) - len(prev) :], prev, times, [str(w) for w in weathers])
    return mpc, data, starts
