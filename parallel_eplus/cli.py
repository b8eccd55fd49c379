"""`parallel-eplus`: the command line. Each subcommand is a thin layer over a library function."""

from __future__ import annotations

import argparse
import logging
import os
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
        f"           IT         {summary.get('it_power_kw', float('nan')):10.1f} kW",
        f"           HVAC       {summary.get('hvac_power_kw', float('nan')):10.1f} kW",
    ]
    for zone in ("west", "east"):
        z = {k.removeprefix(zone + "_"): v for k, v in summary.items() if k.startswith(zone + "_")}
        lines.append(
            f"{zone.title():5s} zone  mean {z['temp_mean']:5.2f} C  std {z['temp_std']:4.2f}"
            f"  min {z['temp_min']:5.2f}  max {z['temp_max']:5.2f}  in 22-25 C {z['in_band_pct']:5.1f} %"
        )
    lines.append(f"zone samples in 22-25 C {summary['in_band_pct']:8.2f} %")
    return "\n".join(lines)


def cmd_simulate(args: argparse.Namespace) -> int:
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


def cmd_train(args: argparse.Namespace) -> int:
    from parallel_eplus.buildings.reward import RewardConfig
    from parallel_eplus.training.config import TrainConfig, TRPOSettings
    from parallel_eplus.training.train import train

    cfg = TrainConfig(
        workers=args.workers,
        weathers=[w.strip() for w in args.weathers.split(",") if w.strip()],  # checked by TrainConfig
        model=args.model,
        building=args.building,
        timesteps=args.timesteps,
        run_days=args.run_days,
        batch_size=args.batch_size,
        seed=args.seed,
        run_name=args.run_name,
        checkpoint_every=args.checkpoint_every,
        keep_episodes=args.keep_episodes,
        backend=args.backend,
        ray_address=args.ray_address,
        workers_per_actor=args.workers_per_actor,
        lockstep=args.lockstep,
        time_features=args.time_features,
        schedule_features=args.schedule_features,
        init_from=str(args.init_from) if args.init_from else None,
        residual_scale=args.residual,
        residual_space=args.residual_space,
        rbc_target_c=args.rbc_target,
        algorithm=args.algorithm,
        reward=RewardConfig.from_any(args.reward),
        trpo=TRPOSettings(log_std_init=args.log_std_init),
    )
    if args.resume and "--timesteps" not in sys.argv:
        cfg.timesteps = 0  # 0: keep the resumed run's own total
    try:
        final = train(cfg, resume=args.resume, progress=not args.quiet)
    except KeyboardInterrupt:
        return 130
    run_dir = final.parent
    print(f"model: {final} (observation statistics: {run_dir / 'vecnormalize.pkl'})")
    print(f"episode records: {run_dir / 'episodes.csv'}")
    tensorboard = Path(sys.executable).parent / "tensorboard"
    print(f"TensorBoard: {tensorboard} --logdir {cfg.tensorboard_dir}   (then open http://localhost:6006)")
    return 0


def _temperatures(text: str, flag: str) -> list[float]:
    try:
        return [float(t) for t in text.split(",")]
    except ValueError:
        raise ValueError(f"{flag} takes zone temperatures in °C, comma-separated (e.g. 22.7,23.5): {text!r}") from None


def cmd_evaluate(args: argparse.Namespace) -> int:
    from parallel_eplus.buildings.reward import RewardConfig
    from parallel_eplus.evaluation.sweep import (
        BASELINE_LABEL,
        RBC_LABEL,
        Controller,
        policy_controller,
        run_sweep,
        write_results,
    )

    weathers = [w.strip() for w in args.weathers.split(",") if w.strip()]  # checked by run_sweep first
    controllers = []
    if args.baseline:
        controllers.append(Controller(BASELINE_LABEL, "baseline"))
    if args.rbc:
        controllers.append(Controller(RBC_LABEL, "rbc"))
    for target in _temperatures(args.rbc_targets, "--rbc-targets") if args.rbc_targets else []:
        controllers.append(Controller(f"{RBC_LABEL} ({target:g} °C)", "rbc", rbc_target_c=target))
    controllers += [policy_controller(p) for p in args.policy or []]
    if not controllers:
        raise ValueError("nothing to evaluate: give --baseline, --rbc, --rbc-targets and/or --policy PATH")
    histogram = tuple(args.histogram.rsplit(",", 1)) if args.histogram else None  # labels may hold commas
    df = run_sweep(
        controllers, weathers, args.run_days, args.workers, args.out, RewardConfig.from_any(args.reward),
        not args.quiet, args.building,
    )  # fmt: skip
    if args.online:
        import pandas as pd

        from parallel_eplus.evaluation.online import run_online

        policies = [c for c in controllers if c.kind == "policy"]
        if not policies:
            raise ValueError("--online needs --policy: only a learning policy can keep learning")
        online = run_online(policies, weathers, args.run_days, args.workers, args.out, args.online_batch)
        df = pd.concat([df, online], ignore_index=True)
    files = write_results(df, args.out, histogram)
    print((args.out / "results.md").read_text())
    print("written: " + ", ".join(str(f) for f in files))
    return 0


def cmd_plot(args: argparse.Namespace) -> int:
    from parallel_eplus.evaluation.plots import plot_path

    written = plot_path(args.path)
    for path in written if isinstance(written, list) else [written]:
        print(f"written: {path}")
    return 0


def cmd_bench(args: argparse.Namespace) -> int:
    from parallel_eplus.evaluation.bench import BenchConfig, format_table, replay_run, run

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
        workers=args.workers, repeats=args.repeats,
    )  # fmt: skip
    results = run(cfg, args.out)
    print(format_table(results))
    print(f"written: {args.out}")
    return 0


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="parallel-eplus", description=__doc__)
    parser.add_argument("-v", "--verbose", action="store_true", help="debug logging")
    sub = parser.add_subparsers(dest="command", required=True)

    sim = sub.add_parser("simulate", help="run one episode and print the paper's episode statistics")
    sim.add_argument("--weather", default="CA", help="CA, CO, FL, IL, VA or a path to an .epw (default CA)")
    sim.add_argument("--days", type=int, default=7, help="run period length from Jan 1 (default 7)")
    sim.add_argument("--model", default="temp_fan", choices=["temp_fan", "temp"])
    sim.add_argument("--building", help="a building spec (TOML); default: the data center")
    sim.add_argument("--policy", default="constant", choices=["constant", "random"])
    sim.add_argument("--action", help="the constant action in [-1, 1], comma-separated (default all 0)")
    sim.add_argument("--output-dir", type=Path, help="keep the episode records here")
    sim.add_argument("--reward", type=Path, help="JSON file overriding reward constants")
    sim.add_argument("--seed", type=int, default=0)
    sim.add_argument("--quiet", action="store_true", help="no progress bar")
    sim.set_defaults(func=cmd_simulate)

    tr = sub.add_parser("train", help="train TRPO (or PPO) on parallel EnergyPlus workers (paper settings by default)")
    tr.add_argument("--workers", type=int, default=os.cpu_count() or 1, help="EnergyPlus processes (default: cores)")
    tr.add_argument("--weathers", default="CA", help="comma-separated, e.g. CA,CO,FL (default CA)")
    tr.add_argument("--model", default="temp_fan", choices=["temp_fan", "temp"])
    tr.add_argument("--building", help="a building spec (TOML), checked first; default: the data center")
    tr.add_argument(
        "--time-features", action="store_true",
        help="add hour and day of week (sine/cosine) to the paper's six observations",
    )  # fmt: skip
    tr.add_argument(
        "--schedule-features", action="store_true",
        help="add the IT-load schedule: the coming step's load, its last and next change, and how far away",
    )  # fmt: skip
    tr.add_argument(
        "--algorithm", default="trpo", choices=["trpo", "ppo", "sac"],
        help="trpo: the paper's (sb3-contrib), default; ppo: Stable-Baselines3's, same network and discounting; "
        "sac: Stable-Baselines3's off-policy SAC (training/config.py SACSettings; --batch-size is unused)",
    )  # fmt: skip
    tr.add_argument(
        "--residual", type=float, default=0.0, metavar="SCALE",
        help="the policy corrects the rule-based controller's action by up to SCALE (e.g. 0.2) instead of acting alone",
    )  # fmt: skip
    tr.add_argument(
        "--residual-space", default="action", choices=["action", "demand"],
        help="with --residual: correct each normalized action (default) or each zone's flow demand (SCALE in kg/s)",
    )  # fmt: skip
    tr.add_argument("--rbc-target", type=float, help="with --residual: the rule-based controller's zone target, C")
    tr.add_argument(
        "--log-std-init", type=float, default=0.0,
        help="the new policy's log standard deviation (default 0, the paper's; --init-from keeps the saved one)",
    )  # fmt: skip
    tr.add_argument("--timesteps", type=int, default=1_000_000, help="total env steps (default 1e6)")
    tr.add_argument("--run-days", type=int, default=365, help="episode length in days from Jan 1 (default 365)")
    tr.add_argument("--batch-size", type=int, default=16384, help="steps per TRPO update, split across workers")
    tr.add_argument("--seed", type=int, default=0)
    tr.add_argument("--run-name", help="default: trpo-<weathers>-<time>")
    tr.add_argument("--resume", help="a checkpoint .zip or a run directory to continue")
    tr.add_argument(
        "--init-from", type=Path,
        help="start a new run from a saved model.zip's weights and observation statistics (fine-tuning)",
    )  # fmt: skip
    tr.add_argument("--checkpoint-every", type=int, default=100_000, help="env steps between checkpoints")
    tr.add_argument("--keep-episodes", type=int, default=2, help="full episode directories kept per worker")
    tr.add_argument("--backend", default="local", choices=["local", "ray"])
    tr.add_argument("--ray-address", help="an existing Ray cluster (default: start Ray locally)")
    tr.add_argument("--workers-per-actor", type=int, help="Ray: EnergyPlus workers hosted by each actor")
    tr.add_argument(
        "--lockstep", action="store_true",
        help="step all workers together (a seed then fixes the run bit for bit). Default: each "
        "local worker gets its next action as soon as its observation arrives",
    )  # fmt: skip
    tr.add_argument("--reward", type=Path, help="JSON file overriding reward constants")
    tr.add_argument("--quiet", action="store_true", help="no progress bar")
    tr.set_defaults(func=cmd_train)

    ev = sub.add_parser("evaluate", help="controllers x weathers sweep: the paper's table and figures")
    ev.add_argument("--policy", action="append", help="a trained model.zip (or run dir); PATH=LABEL sets the label")
    ev.add_argument("--baseline", action="store_true", help="include EnergyPlus's built-in controller")
    ev.add_argument("--rbc", action="store_true", help="include the rule-based controller")
    ev.add_argument(
        "--rbc-targets", metavar="C,C,...",
        help="the rule-based controller once per zone target (°C), e.g. 22.7,23.5: what the reward pays for each",
    )  # fmt: skip
    ev.add_argument("--weathers", default="CA,CO,FL,IL,VA")
    ev.add_argument("--building", help="a building spec (TOML), checked first; default: the data center")
    ev.add_argument("--run-days", type=int, default=365)
    ev.add_argument("--workers", type=int, default=os.cpu_count() or 1, help="episodes run at once")
    ev.add_argument("--out", type=Path, default=Path("results") / "latest")
    ev.add_argument("--histogram", help="CONTROLLER,WEATHER for the West-zone histogram (default: last, VA)")
    ev.add_argument("--reward", type=Path, help="JSON file overriding reward constants")
    ev.add_argument(
        "--online", action="store_true",
        help="also the paper's protocol: each --policy (TRPO/PPO) keeps learning, stochastic, on each weather for "
        "one episode (a copy; the saved model is untouched); rows labelled '..., online'",
    )  # fmt: skip
    ev.add_argument("--online-batch", type=int, help="with --online: steps per update (default: the run's own)")
    ev.add_argument("--quiet", action="store_true", help="no progress bar")
    ev.set_defaults(func=cmd_evaluate)

    be = sub.add_parser("bench", help="measure our overhead against raw EnergyPlus on this machine")
    be.add_argument("--weather", default="CA")
    be.add_argument("--days", type=int, default=365, help="period for the raw and env runs (default a year)")
    be.add_argument("--train-steps", type=int, default=16384, help="env steps of TRPO learn (default one batch)")
    be.add_argument(
        "--vector-steps", type=int, help="vector steps per worker (default: the same simulated days as training)"
    )
    be.add_argument("--workers", type=int, default=os.cpu_count() or 1)
    be.add_argument("--repeats", type=int, default=3, help="repetitions; medians are reported")
    be.add_argument("--out", type=Path, default=Path("results") / "bench.json")
    be.add_argument(
        "--replay-run", type=Path, metavar="RUN_DIR",
        help="instead: replay a training run's actions in raw EnergyPlus (needs its step tables: --keep-episodes)",
    )  # fmt: skip
    be.set_defaults(func=cmd_bench)

    bd = sub.add_parser("building", help="building spec files (buildings/spec.py)")
    from parallel_eplus.buildings.commands import add_check

    add_check(bd.add_subparsers(dest="building_command", required=True))

    pl = sub.add_parser(
        "plot", help="RUN_DIR: convergence; EPISODE_DIR: its time series; SWEEP_DIR: figures from results.csv"
    )
    pl.add_argument("path", type=Path)
    pl.set_defaults(func=cmd_plot)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    logging.basicConfig(
        level=logging.DEBUG if args.verbose else logging.INFO,
        format="%(asctime)s %(levelname)s %(name)s: %(message)s",
    )
    from parallel_eplus.errors import EnergyPlusError, Interrupts

    try:
        with Interrupts():  # every command cleans up on Ctrl-C or SIGTERM, started in the background or not
            return args.func(args)
    except (EnergyPlusError, ValueError, FileNotFoundError) as e:
        log.error("%s", e)
        return 2
    except KeyboardInterrupt:
        log.warning("interrupted")
        return 130


if __name__ == "__main__":
    sys.exit(main())
