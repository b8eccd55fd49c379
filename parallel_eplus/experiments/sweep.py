"""Many trainings as one workload: a sweep's trials (seeds times a grid, or a search) as Ray Tune trials.

Each trial asks Ray for the cores its EnergyPlus workers need (`workers` CPUs; the learner, which mostly
waits on them, shares those cores), so trials queue while the machine or cluster is full, and each trial's
workers run on one node. A failed trial is reported and the others go on. Locally the sweep starts a Ray of
its own; with an address it joins that cluster, our package shipped with the job (envs/ray_session.py).

Each trial is an ordinary run: `runs/<sweep>/<trial>/` (what `evaluate`, `plot` and `train --resume` read)
and `tensorboard_logs/<sweep>/<trial>/`, so the trials overlay in TensorBoard. Ray Tune's own records of each
attempt go to `runs/<sweep>/_tune/<time>/` (progress.csv and result.json per trial).

Resuming: running the same sweep again continues it trial by trial from each run folder's last checkpoint
(a finished trial only reloads its model), because trial names follow from their settings. We chose this
over Tune's experiment restore, which unpickles the experiment's saved state and keeps its old settings:
here the spec is compared with the one saved in `runs/<sweep>/sweep.json` and a changed spec is refused
(only `timesteps` may grow). A search, run again, draws new trials; those it finished keep their folders.

Ctrl-C or SIGTERM (`ray job stop`) stops every trial as Ctrl-C stops `train`: at its current batch, with a
checkpoint, its EnergyPlus workers and pipes gone; then the sweep ends (exit code 130).
"""

from __future__ import annotations

import json
import logging
import os
import signal
import time
from dataclasses import dataclass, field
from pathlib import Path

from parallel_eplus import io
from parallel_eplus.errors import RunExistsError
from parallel_eplus.experiments.sweep_rank import best_of, trial_evaluation, write_choice
from parallel_eplus.experiments.sweep_spec import SweepSpec, evaluates, trial_name
from parallel_eplus.runs.policy_files import MODEL_FILE, saves_newest_first

log = logging.getLogger(__name__)

EXPERIMENT = "experiment"  # runs/<sweep>/_tune/experiment/: one Tune experiment per sweep, continued on a re-run


@dataclass
class TrialOutcome:
    """How one trial ended, as the sweep reports it."""

    name: str
    state: str  # finished, failed, stopped, early-stopped (by the scheduler), pending
    run_dir: Path
    timesteps: int = 0
    in_band_pct: float = float("nan")
    power_kw: float = float("nan")
    reward: float = float("nan")
    error: str = ""
    evaluation: dict = field(default_factory=dict)  # its best evaluation (sweep_rank.trial_evaluation)


def _quiet_tune_hints(record: logging.LogRecord) -> bool:
    """Drop Tune's advice that does not apply here: its restore call (re-running the sweep resumes it) and
    the missing metrics of trials that had not started."""
    text = record.getMessage()
    return "Tuner.restore" not in text and "Failed to fetch metrics" not in text


def _param_space(spec: SweepSpec) -> dict:
    from ray import tune

    space: dict = {key: tune.grid_search(values) for key, values in spec.grid.items()}
    space["seed"] = tune.grid_search(spec.seeds) if len(spec.seeds) > 1 else spec.seeds[0]
    if spec.search is not None:
        for key, dist in spec.search.space.items():
            kind, args = next(iter(dist.items()))
            space[key] = tune.choice(args) if kind == "choice" else getattr(tune, kind)(*args)
    return space


def _claim(spec: SweepSpec, root: Path, tb_root: Path, overwrite: bool) -> bool:
    """A sweep's folder holds one sweep: the same spec continues it, another is refused (or moved aside).
    True: the same spec with the same steps (its Tune experiment is restored as it was)."""
    saved = root / "sweep.json"
    same = False
    if saved.is_file() and not overwrite:
        old, new = json.loads(saved.read_text()), json.loads(spec.to_json())
        old.setdefault("scheduler", None)  # sweeps from before [scheduler]
        same = old == new
        old["base"].pop("timesteps", None), new["base"].pop("timesteps", None)
        if old != new:
            raise RunExistsError(
                f"{root} holds a sweep with other settings ({saved}): re-run that sweep to continue it, or use another "
                "name, or --overwrite (moves the old sweep aside, deletes nothing)"
            )
        log.info("sweep %s: continuing; each trial resumes from its last checkpoint", spec.name)
    elif overwrite:
        stamp = time.strftime("%Y%m%d-%H%M%S")
        for folder in (root, tb_root):
            if folder.exists():
                folder.rename(folder.with_name(f"{folder.name}.old-{stamp}"))
                log.warning("--overwrite: moved %s aside to %s.old-%s", folder, folder.name, stamp)
    elif root.exists() and any(root.iterdir()):
        raise RunExistsError(f"{root} exists and is not a sweep's folder: use another name, or --overwrite")
    root.mkdir(parents=True, exist_ok=True)
    io.write_text(saved, spec.to_json())
    return same


def run_tune_sweep(spec: SweepSpec, ray_address: str | None = None, overwrite: bool = False) -> list[TrialOutcome]:
    """Run every trial of `spec` (queued by cores, on this machine or the cluster at `ray_address`)."""
    import importlib.util

    if importlib.util.find_spec("ray") is None:
        raise ValueError("seeds and sweeps run on Ray Tune: .venv/bin/pip install 'ray[default]' (setup.sh does)")
    import ray
    from ray import tune
    from ray.tune.logger import CSVLoggerCallback, JsonLoggerCallback

    from parallel_eplus.envs.ray_session import connect
    from parallel_eplus.experiments.tune_schedulers import concurrency, make_scheduler
    from parallel_eplus.experiments.tune_trial import TrialRun

    root = Path(spec.runs_dir).resolve() / spec.name
    tb_root = Path(spec.tensorboard_dir).resolve() / spec.name
    if spec.search is not None and importlib.util.find_spec("optuna") is None:
        raise ValueError("a [search] needs Optuna: .venv/bin/pip install optuna (a grid or seeds do not)")
    same = _claim(spec, root, tb_root, overwrite)
    base_workers = int(spec.base.get("workers", os.cpu_count() or 1))
    varied = spec.varied
    numbered = spec.search is not None

    def name_of(trial) -> str:
        return trial_name(trial.config, varied, trial.trial_id if numbered else None)

    trainable = tune.with_resources(
        tune.with_parameters(TrialRun, base=spec.base, runs_dir=str(root), tensorboard_dir=str(tb_root)),
        lambda config: {"cpu": int(config.get("workers", base_workers))},
    )
    search_alg = None
    if spec.search is not None:
        from ray.tune.search.optuna import OptunaSearch

        search_alg = OptunaSearch(metric=spec.search.metric, mode=spec.search.mode, seed=spec.seeds[0])
    os.environ["TUNE_DISABLE_AUTO_CALLBACK_LOGGERS"] = "1"  # ours is TensorBoard under tensorboard_logs/
    for name in ("ray.tune.tune", "ray.tune.analysis.experiment_analysis"):
        logging.getLogger(name).addFilter(_quiet_tune_hints)
    started = connect(ray_address, os.cpu_count() or 1)
    old_term = signal.signal(signal.SIGTERM, lambda *_: os.kill(os.getpid(), signal.SIGINT))  # Tune's graceful stop
    try:
        at_once = concurrency(spec, int(ray.cluster_resources().get("CPU", os.cpu_count() or 1)))
        log.info("sweep %s: up to %d trial(s) at once", spec.name, at_once)
        # A grid's trials all exist from the start and queue for cores (the closing table lists those that never
        # started as pending); a search draws its next trial only when one may start.
        limit = at_once if spec.search is not None else None
        experiment = root / "_tune" / EXPERIMENT
        if same and tune.Tuner.can_restore(experiment):  # the same sweep again: its one Tune experiment goes on
            tuner = tune.Tuner.restore(str(experiment), trainable, resume_unfinished=True, resume_errored=True)
        else:  # new, or more steps (finished trials must run again): a new experiment in the same folder
            tuner = tune.Tuner(
                trainable,
                param_space=_param_space(spec),
                tune_config=tune.TuneConfig(
                    num_samples=spec.search.samples if spec.search else 1, search_alg=search_alg,
                    scheduler=make_scheduler(spec), max_concurrent_trials=limit,
                    trial_name_creator=name_of, trial_dirname_creator=name_of, reuse_actors=False,
                ),
                run_config=tune.RunConfig(
                    name=EXPERIMENT, storage_path=str(root / "_tune"), verbose=1,
                    failure_config=tune.FailureConfig(max_failures=0),
                    checkpoint_config=tune.CheckpointConfig(checkpoint_at_end=False),
                    callbacks=[JsonLoggerCallback(), CSVLoggerCallback()],
                ),
            )  # fmt: skip
        grid = tuner.fit()
    finally:
        signal.signal(signal.SIGTERM, old_term)
        if started:
            ray.shutdown()
    return [_outcome(result, root) for result in grid]


def _outcome(result, root: Path) -> TrialOutcome:
    metrics = result.metrics or {}
    name = Path(result.path).name
    outcome = TrialOutcome(name=name, state="pending", run_dir=root / name, evaluation=trial_evaluation(root / name))
    for key in ("timesteps", "in_band_pct", "power_kw", "reward"):
        if key in metrics:
            setattr(outcome, key, metrics[key])
    if result.error is not None:
        text = str(result.error).strip().splitlines()
        cause = next((ln for ln in text if ln.startswith("RuntimeError: ")), text[-1] if text else "")
        outcome.state, outcome.error = "failed", cause.removeprefix("RuntimeError: ")
    elif metrics.get("done") and not metrics.get("stopped") and metrics.get("finished", True):
        outcome.state = "finished"
    elif metrics.get("done") and not metrics.get("stopped"):  # Tune marks done the result its scheduler stops at
        outcome.state = "early-stopped"
    elif metrics.get("training_iteration"):  # stopped by the sweep's stop, or its own process's signal
        outcome.state = "stopped"
        saves = saves_newest_first(outcome.run_dir)  # the stop's checkpoint, after the last reported batch
        if saves and saves[0].name != MODEL_FILE:
            outcome.timesteps = max(outcome.timesteps, int(saves[0].stem.split("_")[1]))
    return outcome


def format_outcomes(outcomes: list[TrialOutcome], spec: SweepSpec | None = None) -> str:
    """The sweep's closing table: one line per trial (the best marked `<- best`), each failure's cause, and the best
    trial's configuration as a ready command (written to the sweep's folder too: sweep_rank.write_choice)."""
    evaluated = spec is not None and evaluates(spec)
    w = max([28] + [len(o.name) for o in outcomes])
    head = f"{'trial':<{w}} {'state':<13} {'steps':>8} {'in band %':>9} {'power kW':>9} {'reward':>7}"
    lines = [head + (f" {'eval: in band %':>15} {'energy %':>8} {'score':>8} {'at step':>8}" if evaluated else "")]
    best, how = _best(outcomes, spec)
    for o in outcomes:
        line = (f"{o.name:<{w}} {o.state:<13} {o.timesteps:>8} {o.in_band_pct:>9.2f} "
                f"{o.power_kw:>9.1f} {o.reward:>7.3f}")  # fmt: skip
        if evaluated:
            e = o.evaluation or trial_evaluation(o.run_dir)
            line += (f" {e['eval_in_band_pct']:>15.2f} {e['eval_energy_change_pct']:>+8.2f} {e['eval_score']:>8.2f} "
                     f"{e['eval_timesteps']:>8}")  # fmt: skip
        lines.append(line + ("  <- best" if o is best else ""))
    lines += [f"{o.name} failed: {o.error}" for o in outcomes if o.state == "failed"]
    if best is not None:
        lines.append(f"best by {how}: {best.name}")
        if (best.run_dir / "config.json").is_file():
            from parallel_eplus.training.config import TrainConfig

            lines += write_choice(best.run_dir.parent, spec.name, best.run_dir, json.loads(TrainConfig().to_json()))
            lines.append(f"written: {best.run_dir.parent / 'best.toml'}, {best.run_dir.parent / 'best-command.txt'}")
    return "\n".join(lines)


def _best(outcomes: list[TrialOutcome], spec: SweepSpec | None) -> tuple[TrialOutcome | None, str]:
    """By evaluation when the trials evaluate (their best evaluation's score: eval_target.py), else by a
    search's metric over its finished trials; none for a grid or seeds without evaluation."""
    if spec is not None and evaluates(spec):
        target = spec.base.get("evaluation.target")
        rows = [{"o": o, **(o.evaluation or trial_evaluation(o.run_dir))} for o in outcomes if o.state != "failed"]
        pick = best_of(rows, "eval_score", "max")
        how = f"evaluation (target {target}: met, then lowest energy)" if target else "evaluation (mean reward)"
        return (pick["o"] if pick else None), how
    search = spec.search if spec is not None else None
    if search is None:
        return None, ""
    rows = [{"o": o, search.metric: getattr(o, search.metric)} for o in outcomes if o.state == "finished"]
    pick = best_of(rows, search.metric, search.mode)
    return (pick["o"] if pick else None), f"{search.metric} ({search.mode})"
