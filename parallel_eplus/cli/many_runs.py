"""The subcommands over many runs: seeds and sweeps as Ray Tune trials (`train --seeds`, `sweep`), and the run
registry (`runs`, `runs show`, `runs stop`)."""

from __future__ import annotations

import argparse
import logging
import sys
from pathlib import Path

log = logging.getLogger("parallel_eplus")


def train_seeds(cfg, args: argparse.Namespace) -> int:
    from parallel_eplus.experiments.sweep_spec import seeds_spec

    if args.resume or args.backend == "ray":
        raise ValueError(
            "--seeds runs each seed as a Ray Tune trial with its workers on one node: drop --backend ray "
            "(--ray-address sends the trials to a cluster) and --resume (re-run the command to continue)"
        )
    try:
        seeds = [int(s) for s in args.seeds.split(",") if s.strip()]
    except ValueError:
        raise ValueError(f"--seeds takes whole numbers, comma-separated (e.g. 0,1,2): {args.seeds!r}") from None
    cfg.run_name = cfg.run_name or cfg.resolved().run_name
    return _run_sweep(seeds_spec(cfg, seeds), args.ray_address, args.overwrite)


def cmd_sweep(args: argparse.Namespace) -> int:
    from parallel_eplus.experiments.sweep_spec import load_spec

    return _run_sweep(load_spec(args.spec), args.ray_address, args.overwrite)


def _run_sweep(spec, ray_address: str | None, overwrite: bool) -> int:
    from parallel_eplus.experiments.sweep import format_outcomes, run_tune_sweep

    outcomes = run_tune_sweep(spec, ray_address, overwrite)
    print(format_outcomes(outcomes, spec))
    root = outcomes[0].run_dir.parent if outcomes else spec.runs_dir
    print(f"runs: {root}/<trial>/   TensorBoard: {Path(sys.executable).parent / 'tensorboard'} --logdir "
          f"{Path(spec.tensorboard_dir).resolve() / spec.name}")  # fmt: skip
    if any(o.state in ("stopped", "pending") for o in outcomes):
        log.warning("sweep %s stopped; run the same command again to continue each trial from its last checkpoint",
                    spec.name)  # fmt: skip
        return 130
    return 1 if any(o.state == "failed" for o in outcomes) else 0


def cmd_runs(args: argparse.Namespace) -> int:
    from parallel_eplus.experiments import registry_view
    from parallel_eplus.runs import registry

    if args.runs_command is None:
        runs = registry.list_runs(args.dir)
        print(registry_view.table(runs) if runs else f"no runs in {args.dir}")
        return 0
    if args.runs_command == "show":
        from parallel_eplus.experiments.sweep_view import find_sweep, sweep_table

        sweep = find_sweep(args.name, args.dir)
        if sweep is not None:
            print(sweep_table(sweep))
            return 0
    info = registry.read_run(registry.resolve_run(args.name, args.dir), args.dir)
    if args.runs_command == "show":
        print(registry_view.details(info))
        return 0
    print(f"stopping {info.name} ({info.process}) ...", flush=True)
    try:
        info, left = registry.stop_run(info, args.timeout)
    except TimeoutError as e:
        print(f"{e}: it may still be saving; run `parallel-eplus runs` again to see", file=sys.stderr)
        return 1
    print(f"{info.name}: {info.state} at step {info.steps}; checkpoint: {info.checkpoint or 'none'}")
    if left:
        print("left behind: " + "; ".join(left) + " (parallel-eplus clean --kill removes them)")
        return 1
    print(f"no EnergyPlus process or pipe left; continue it with: parallel-eplus train --resume {info.path}")
    return 0
