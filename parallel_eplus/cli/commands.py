"""The subcommands of `parallel-eplus`: each a thin layer over a library function, imported when it runs."""

from __future__ import annotations

import argparse
import importlib.util
import logging
import sys
import tempfile
from pathlib import Path

import numpy as np

log = logging.getLogger("parallel_eplus")


def _format_summary(summary: dict) -> str:
    lines = [
        f"weather {summary.get('weather')}  model {summary.get('model')}  steps {summary.get('steps', 0):.0f}",
        f"mean reward           {summary.get('reward_mean', float('nan')):10.3f}",
        f"mean power total      {summary.get('power_kw', float('nan')):10.1f} kW",
    ]
    for part in ("IT", "HVAC"):  # the data center's power split, where a building has it
        if f"{part.lower()}_power_kw" in summary:
            lines.append(f"           {part:<4}       {summary[f'{part.lower()}_power_kw']:10.1f} kW")
    # every temperature the reward watches: the data center's "west"/"east", any spec's own names
    temps = [k.removesuffix("_temp_mean") for k in summary if k.endswith("_temp_mean")]
    for name in temps:
        z = {k.removeprefix(name + "_"): v for k, v in summary.items() if k.startswith(name + "_")}
        label = f"{name.title()} zone" if name in ("west", "east") else name
        lines.append(
            f"{label:10s}  mean {z['temp_mean']:5.2f} C  std {z['temp_std']:4.2f}"
            f"  min {z['temp_min']:5.2f}  max {z['temp_max']:5.2f}  in band {z['in_band_pct']:5.1f} %"
        )
    where = (
        ""
        if summary.get("comfort_steps_pct", 100.0) == 100.0
        else (f" (where comfort applies: {summary['comfort_steps_pct']:.1f} % of steps)")
    )
    lines.append(f"samples in band       {summary['in_band_pct']:8.2f} %{where}")
    if "energy_kwh" in summary:  # BOPTEST's figures (buildings/scoring/comfort.py)
        lines.append(f"discomfort            {summary['discomfort_kh']:8.2f} K·h per zone")
        lines.append(f"energy, every fuel    {summary['energy_kwh']:8.1f} kWh")
        lines.append(f"peak electric power   {summary['peak_power_kw']:8.1f} kW")
    return "\n".join(lines)


def cmd_simulate(args: argparse.Namespace) -> int:
    if args.bacnet:
        return _simulate_bacnet(args)
    from tqdm import tqdm

    from parallel_eplus.envs.env import EnergyPlusEnv

    env = EnergyPlusEnv(
        weather=args.weather,
        model=args.model,
        building=args.building,
        run_days=args.days,
        output_dir=args.output_dir,
        reward=args.reward,
    )
    try:
        env.action_space.seed(args.seed)
        obs, info = env.reset(seed=args.seed)
        constant = np.zeros(env.action_space.shape, dtype=np.float32)
        if args.action:
            constant = np.array([float(v) for v in args.action.split(",")], dtype=np.float32)
        total = env.sim.steps_per_episode
        with tqdm(total=total, desc=f"simulate {args.weather}", unit="step", disable=args.quiet) as bar:
            terminated = False
            while not terminated:
                action = env.action_space.sample() if args.policy == "random" else constant
                obs, reward, terminated, _, info = env.step(action)
                bar.update()
        print(_format_summary(info["episode_summary"]))
        if args.output_dir:
            print(f"episode records: {info['episode_dir']}")
    finally:
        env.close()
    return 0


def _simulate_bacnet(args: argparse.Namespace) -> int:
    from parallel_eplus.cli.deploy import needs_bacnet

    needs_bacnet()
    from parallel_eplus.deploy.bacnet.device import DeviceConfig, simulate

    summary = simulate(DeviceConfig(
        args.bacnet, args.device_id, args.building, args.weather, args.days, args.step_seconds, args.point_map,
        args.output_dir, args.warmup, args.watchdog,
    ))  # fmt: skip
    if summary is None:
        return 130
    print(_format_summary(summary))
    if args.output_dir:
        print(f"episode records: {summary['episode_dir']}")
    return 0


def cmd_train(args: argparse.Namespace) -> int:
    from parallel_eplus.buildings.scoring.reward import RewardConfig
    from parallel_eplus.buildings.weather.files import parse_weathers
    from parallel_eplus.learning.model_based.settings import MBPOSettings, MPCSettings
    from parallel_eplus.runs.policy_files import normalization_file
    from parallel_eplus.training.config import (
        ComfortConstraint,
        ImitationSettings,
        SACSettings,
        TrainConfig,
        TRPOSettings,
    )
    from parallel_eplus.training.eval_target import EvalSettings
    from parallel_eplus.training.train import train

    cfg = TrainConfig(
        workers=args.workers,
        # a spec's own short names are checked by TrainConfig against the spec
        weathers=[w.strip() for w in args.weathers.split(",") if w.strip()]
        if args.building
        else parse_weathers(args.weathers),
        model=args.model,
        building=args.building,
        timesteps=args.timesteps,
        run_days=args.run_days,
        random_start=args.random_start,
        batch_size=args.batch_size,
        seed=args.seed,
        run_name=args.run_name,
        checkpoint_every=args.checkpoint_every,
        keep_episodes=args.keep_episodes,
        backend=args.backend,
        ray_address=args.ray_address,
        workers_per_actor=args.workers_per_actor,
        lockstep=args.lockstep,
        overlap=args.overlap,
        max_restarts=args.max_restarts,
        step_timeout_s=args.step_timeout,
        time_features=args.time_features,
        schedule_features=args.schedule_features,
        init_from=str(args.init_from) if args.init_from else None,
        residual_scale=args.residual,
        residual_space=args.residual_space,
        rbc_target_c=args.rbc_target,
        algorithm=args.algorithm,
        preset=getattr(args, "preset", None),
        reward=RewardConfig.from_any(args.reward),
        comfort=ComfortConstraint(target_pct=args.comfort_target, margin_c=args.comfort_margin),
        objective=args.objective,
        init_from_baseline=args.init_from_baseline,
        weather_noise=args.weather_noise,
        forecast_hours=args.forecast,
        forecast_error=args.forecast_error,
        trpo=TRPOSettings(
            log_std_init=args.log_std_init, gamma=args.gamma, gae_lambda=args.gae_lambda, sde_sample_freq=args.sde_freq
        ),  # fmt: skip
        sac=SACSettings.from_text(args.sac, SACSettings(gamma=args.gamma)),
        evaluation=EvalSettings(
            every=args.eval_every,
            weathers=[w.strip() for w in (args.eval_weathers or "").split(",") if w.strip()],
            days=args.eval_days,
            target=args.target,
            scenarios=[s.strip() for s in args.eval_scenarios.split(",") if s.strip()],
        ),  # fmt: skip
        mpc=MPCSettings.from_text(args.mpc),
        mbpo=MBPOSettings.from_text(args.mbpo),
    )
    given = set(getattr(args, "from_config", {}))  # what `--config FILE` set counts as given, as a flag does
    if args.init_from_baseline and ("--log-std-init" in sys.argv or "log_std_init" in given):  # the clone's exploration
        cfg.imitation = ImitationSettings(log_std=args.log_std_init)
    if args.resume and "--timesteps" not in sys.argv and "timesteps" not in given:
        cfg.timesteps = 0  # 0: keep the resumed run's own total
    if "--batch-size" not in sys.argv and "batch_size" not in given and cfg.workers > 0:  # the default, split evenly
        cfg.batch_size = -(-cfg.batch_size // cfg.workers) * cfg.workers
    if args.seeds:
        from parallel_eplus.cli.many_runs import train_seeds

        return train_seeds(cfg, args)
    try:
        final = train(cfg, resume=args.resume, progress=not args.quiet, overwrite=args.overwrite)
    except KeyboardInterrupt:
        return 130
    if final.suffix == ".zip":
        run_dir = final.parent
        print(f"model: {final} (observation statistics: {normalization_file(final)})")
    else:  # runs/<name>/planner/planner.pt: no policy distilled (no planner steps to distil from, or switched off)
        run_dir = final.parent.parent
        print(f"planner: {final.parent} (evaluate --policy {final.parent})")
    print(f"episode records: {run_dir / 'episodes.csv'}")
    tensorboard = Path(sys.executable).parent / "tensorboard"
    print(f"TensorBoard: {tensorboard} --logdir {cfg.tensorboard_dir}   (then open http://localhost:6006)")
    return 0


def cmd_plot(args: argparse.Namespace) -> int:
    from parallel_eplus.evaluation.redraw import plot_path

    if (args.path / "sweep.json").is_file():  # a training sweep's folder: its learning curves over seeds
        from parallel_eplus.experiments.sweep_curves import plot_sweep

        print(f"written: {plot_sweep(args.path)}")
        return 0
    written = plot_path(args.path)
    for path in written if isinstance(written, list) else [written]:
        print(f"written: {path}")
    return 0


def cmd_building_init(args: argparse.Namespace) -> int:
    from parallel_eplus.buildings.starter.write import init_spec

    out, summary = init_spec(args.idf, args.weather, args.output, args.name)
    print("\n".join(summary))
    print(f"written: {out} (a starter: uncomment the actions the agent should own)")
    return 0


def cmd_building_check(args: argparse.Namespace) -> int:
    from parallel_eplus.buildings.check.names import check_spec
    from parallel_eplus.buildings.resources import spec_file
    from parallel_eplus.buildings.spec.load import load_spec

    spec = load_spec(spec_file(args.spec))  # a path, or a built-in spec's name
    result = check_spec(spec, args.weather, use_cache=not args.no_cache)
    if not result.ok:
        print(f"{spec.path}: {len(result.problems)} problem(s) against {spec.idf.name}:", file=sys.stderr)
        print("  " + "\n  ".join(result.problems), file=sys.stderr)
        return 1
    for note in result.notes:
        print(f"note: {note}")
    n_act = sum(len(a.actuators) for a in spec.actions)
    how = "cached" if result.cached else f"{result.seconds:.1f} s"
    print(f"{spec.name}: ok: {len(spec.observations)} observations, {len(spec.actions)} actions ({n_act} actuators) "
          f"resolved against {spec.idf.name}; {result.timesteps_per_hour} control steps per hour ({how})")  # fmt: skip
    return 0


def cmd_bench(args: argparse.Namespace) -> int:
    from parallel_eplus.bench import BenchConfig, format_table, replay_run, run

    if args.planner:
        import json

        from parallel_eplus.bench.decisions import decisions, format_decisions

        r = decisions(args.planner, repeats=args.repeats, options=args.planner_options, serve=args.served)
        print(format_decisions(r))
        out = args.out.with_name("bench_planner.json") if args.out.name == "bench.json" else args.out
        out.parent.mkdir(parents=True, exist_ok=True)
        out.write_text(json.dumps(r, indent=2) + "\n")
        print(f"written: {out}")
        return 0
    if args.replay_run:
        with tempfile.TemporaryDirectory(prefix="parallel-eplus-replay-") as tmp:
            r = replay_run(args.replay_run, args.workers, Path(tmp))
        print(
            f"{args.replay_run}: {r['episodes']} episodes, {r['steps']:.0f} steps. EnergyPlus alone under the same "
            f"actions, {args.workers} at a time: {r['raw_wall_s'] / 60:.1f} min ({r['raw_steps_per_s']:.0f} steps/s), "
            "start-ups included; the run's own rate is TensorBoard's time/fps."
        )
        return 0
    cfg = BenchConfig(
        weather=args.weather, raw_days=args.days, vector_steps=args.vector_steps, train_steps=args.train_steps,
        workers=args.workers, repeats=args.repeats, building=args.building, short=args.short, boptest=args.boptest,
        ray=not args.no_ray and importlib.util.find_spec("ray") is not None,
    )  # fmt: skip
    results = run(cfg, args.out)
    print(format_table(results))
    print(f"written: {args.out}")
    return 0


def cmd_clean(args: argparse.Namespace) -> int:
    from parallel_eplus.engine.pipes import leftovers

    found = leftovers.leftover_processes()
    for p in found:
        print(f"leftover EnergyPlus process {p.pid} (its trainer is gone; pipe {p.pipe_dir})")
    if found and args.kill:
        leftovers.kill(found)
        print(f"killed {len(found)} leftover EnergyPlus process(es)")
    elif found:
        print("stop them with: parallel-eplus clean --kill")
    stale = leftovers.stale_pipe_dirs(unowned=True)
    for d in stale if args.dry_run else leftovers.sweep(unowned=True):
        print(f"{'stale' if args.dry_run else 'removed'} pipe directory: {d}")
    if not found and not stale:
        print("nothing to clean: no pipe directory or EnergyPlus process of a process that is gone")
    return 0
