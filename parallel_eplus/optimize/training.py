"""The preset's learned controller trained as `train` trains it: the command built from the preset's own settings (its
`[train]` table, long option names as typed), in the building's runs/ folder, stopped with SIGINT when training's
share of the budget is spent (the trainer keeps a checkpoint), continued with `train --resume` by a rerun, and a stopped
run finished where it stood (`train --resume RUN --timesteps STEPS`: nothing left to learn, so the trainer saves its
planner or network) so it can be scored and exported."""

from __future__ import annotations

import json
import logging
from collections.abc import Callable
from pathlib import Path

from parallel_eplus.optimize.candidates import controller_path, option_args
from parallel_eplus.optimize.command import failure, run_command, stage_bar
from parallel_eplus.optimize.folders import BuildingFolder
from parallel_eplus.optimize.settings import (
    QUICK_CHECKPOINT_EVERY,
    QUICK_MPC,
    QUICK_RUN_DAYS,
    QUICK_STUDENT,
    QUICK_TIMESTEPS,
    OptimizeSettings,
)
from parallel_eplus.presets.catalog import Preset

log = logging.getLogger(__name__)

RUN_NAME = "learned"
TRAIN_DEFAULT_TIMESTEPS = 1_000_000  # `train`'s own default, where a preset names none


def run_dir(folder: BuildingFolder) -> Path:
    return folder.runs / RUN_NAME


def run_state(run: Path) -> dict:
    """The run's status.json (state, steps, planned), or {} before it started."""
    try:
        return json.loads((run / "status.json").read_text())
    except (OSError, ValueError):
        return {}


def options(preset: Preset, settings: OptimizeSettings) -> dict:
    """The preset's `[train]` options with optimize's overrides: `--quick`'s, `--run-days`, `--timesteps`,
    `--objective cost`."""
    opts = {k: (dict(v) if isinstance(v, dict) else v) for k, v in preset.commands.get("train", {}).items()}
    if settings.quick:
        opts |= {"run-days": QUICK_RUN_DAYS, "timesteps": QUICK_TIMESTEPS, "checkpoint-every": QUICK_CHECKPOINT_EVERY}
        if opts.get("algorithm") == "mpc":
            opts["mpc"] = opts.get("mpc", {}) | QUICK_MPC | (QUICK_STUDENT if "student" in opts.get("mpc", {}) else {})
    if settings.run_days:
        opts["run-days"] = settings.run_days
    if settings.timesteps:
        opts["timesteps"] = settings.timesteps
    if settings.objective == "cost":
        opts["objective"] = "cost"
    return opts


def timesteps(preset: Preset, settings: OptimizeSettings) -> int:
    return int(options(preset, settings).get("timesteps", TRAIN_DEFAULT_TIMESTEPS))


def acting_from(preset: Preset, settings: OptimizeSettings) -> int:
    """The step from which a planner's own actions drive the run (after its exploration)."""
    from parallel_eplus.learning.model_based.settings import MPCSettings

    return int(options(preset, settings).get("mpc", {}).get("explore_steps", MPCSettings().explore_steps))


def steps_of(run: Path) -> Callable[[], int]:
    return lambda: int(run_state(run).get("steps", 0))


def command(folder: BuildingFolder, spec: Path, preset: Preset, settings: OptimizeSettings) -> list[str]:
    """A new run's `train` command line."""
    return ["train", "--building", str(spec), "--weathers", ",".join(settings.weathers), "--workers",
            str(settings.workers), "--run-name", RUN_NAME, "--seed", "0", "--quiet",
            *option_args(options(preset, settings))]  # fmt: skip


def _progress(run: Path, target: int) -> tuple[int, int, str]:
    steps = int(run_state(run).get("steps", 0))
    return steps, target, "" if steps else "recording the own controls, fitting the model"


def _has_checkpoint(run: Path) -> bool:
    return any((run / "checkpoints").glob("*.pt")) or any((run / "checkpoints").glob("*.zip"))


def train(folder: BuildingFolder, spec: Path, preset: Preset, settings: OptimizeSettings, deadline: Callable[[], float],
          show: bool) -> dict:  # fmt: skip
    """Train (or continue) until the run finishes or `deadline`; returns the stage's fields: state done with the
    steps the controller learned from (`stopped` where the budget cut it), or failed with why."""
    run, target = run_dir(folder), timesteps(preset, settings)
    state = run_state(run)
    if not (state.get("state") == "finished" and int(state.get("steps", 0)) >= target):
        if _has_checkpoint(run):
            args = ["train", "--resume", str(run), "--timesteps", str(target), "--quiet"]
        else:  # new, or stopped before its first checkpoint (while recording the own controls): from the start
            args = command(folder, spec, preset, settings) + (["--overwrite"] if run.exists() else [])
        log.info("%s: training %s (%d steps; %s)", folder.name, preset.name, target,
                 "continuing its checkpoint" if "--resume" in args else "new run")  # fmt: skip
        bar = stage_bar(f"{folder.name}: train {preset.name}", show, target, "step")
        try:
            outcome = run_command(args, folder.logs / "train.log", folder.root, f"train {preset.name}",
                                  deadline=deadline, show=show, bar=bar,
                                  progress=lambda: _progress(run, target))  # fmt: skip
        finally:
            bar.close()
        state = run_state(run)
        if state.get("state") != "finished":
            if not outcome.stopped and outcome.returncode not in (130, -2):
                return {"state": "failed", "error": f"train: {failure(outcome.log)}"}
            if not _has_checkpoint(run):
                return {"state": "failed", "error": "the budget's share for training ended before its first "
                        "checkpoint (while it recorded the own controls): give more --budget-minutes"}  # fmt: skip
            return _finish_where_it_stands(folder, run, preset, target, show)
    path = controller_path(run, preset)
    if not path.exists():
        return {"state": "failed", "error": f"the run finished without {path.name} (see {folder.logs / 'train.log'})"}
    return {"state": "done", "steps": int(state.get("steps", 0)), "planned": target, "stopped": False,
            "wall_s": state.get("wall_s"), "controller": str(path)}  # fmt: skip


def _finish_where_it_stands(folder: BuildingFolder, run: Path, preset: Preset, target: int, show: bool) -> dict:
    """A run stopped at its share of the budget: resumed for zero further steps, so the trainer writes the planner (or
    the network) from its checkpoint; a rerun with more budget continues it (`train --resume`)."""
    steps = int(run_state(run).get("steps", 0))
    outcome = run_command(["train", "--resume", str(run), "--timesteps", str(steps), "--quiet"],
                          folder.logs / "train.log", folder.root, "saving the stopped run's controller",
                          show=show)  # fmt: skip
    path = controller_path(run, preset)
    if outcome.returncode or not path.exists():
        return {"state": "failed", "error": f"saving the stopped run's controller: {failure(outcome.log)}"}
    state = run_state(run)
    log.info("%s: training stopped at its share of the budget, step %d; its controller saved", folder.name, steps)
    return {"state": "done", "steps": int(state.get("steps", steps)), "planned": target, "stopped": True,
            "wall_s": state.get("wall_s"), "controller": str(path)}  # fmt: skip
