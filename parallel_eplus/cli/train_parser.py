"""`train`'s command line (the largest option set, apart so parser.py reads subcommand by subcommand), and the
weather options it shares with `evaluate`."""

from __future__ import annotations

import argparse
import os
from pathlib import Path

from parallel_eplus.cli import commands as c


def add_train(sub) -> argparse.ArgumentParser:
    """The `train` subcommand with its options and defaults (the paper's settings)."""
    tr = sub.add_parser("train", help="train TRPO (or PPO) on parallel EnergyPlus workers (paper settings by default)")
    tr.add_argument("--workers", type=int, default=os.cpu_count() or 1, help="EnergyPlus processes (default: cores)")
    tr.add_argument("--weathers", default="CA", help="comma-separated, e.g. CA,CO,FL (default CA)")
    tr.add_argument("--model", default="temp_fan", choices=["temp_fan", "temp"])
    tr.add_argument(
        "--building", help="a building spec (TOML path or built-in name), checked first; default: the data center"
    )
    tr.add_argument(
        "--time-features", action="store_true",
        help="add hour and day of week (sine/cosine) to the paper's six observations",
    )  # fmt: skip
    tr.add_argument(
        "--schedule-features", action="store_true",
        help="add the IT-load schedule: the coming step's load, its last and next change, and how far away",
    )  # fmt: skip
    weather_options(tr)
    tr.add_argument(
        "--forecast", type=int, default=0, metavar="HOURS",
        help="add the outdoor temperature's next HOURS hours (from the episode's weather file) to the observation",
    )  # fmt: skip
    tr.add_argument("--forecast-error", choices=["low", "medium", "high"],
                    help="with --forecast: BOPTEST's AR(1) forecast error at this level (default: exact)")  # fmt: skip
    tr.add_argument(
        "--algorithm", default="trpo", choices=["trpo", "ppo", "sac", "mpc", "mbpo"],
        help="trpo: the paper's (sb3-contrib), default; ppo: Stable-Baselines3's, same network and discounting; "
        "sac: Stable-Baselines3's off-policy SAC (training/config.py SACSettings; --batch-size is unused); "
        "mpc: learn a model of the building and plan on it, then distil the planner (docs/model-based.md); "
        "mbpo: SAC on real steps and short rollouts of that model, comfort as a constraint (--init-from an mpc run)",
    )  # fmt: skip
    tr.add_argument("--mpc", metavar="NAME=VALUE,...", help="with --algorithm mpc: its settings (docs/model-based.md)")
    tr.add_argument("--sac", metavar="NAME=VALUE,...",
                    help="with --algorithm sac or mbpo: SAC's settings, e.g. ent_coef=0.05,net_arch=64x64 "
                    "(training/config.py SACSettings)")  # fmt: skip
    tr.add_argument("--mbpo", metavar="NAME=VALUE,...",
                    help="with --algorithm mbpo: its settings (docs/model-based.md)")  # fmt: skip
    tr.add_argument(
        "--residual", type=float, default=0.0, metavar="SCALE",
        help="the policy corrects the rule-based controller's action by up to SCALE (e.g. 0.2) instead of acting "
        "alone; with --residual-space builtin, the building's own setpoint schedules",
    )  # fmt: skip
    tr.add_argument(
        "--residual-space", default="action", choices=["action", "demand", "builtin"],
        help="with --residual: correct each normalized action (default) or each zone's flow demand (SCALE in kg/s) "
        "of the rule-based controller, or (builtin) the building's own thermostat schedules by up to SCALE of half "
        "each action's range: a zero correction runs the building's own controls exactly",
    )  # fmt: skip
    tr.add_argument("--rbc-target", type=float, help="with --residual: the rule-based controller's zone target, C")
    tr.add_argument(
        "--log-std-init", type=float, default=0.0,
        help="the new policy's log standard deviation (default 0, the paper's; --init-from keeps the saved one; "
        "with --init-from-baseline the cloned policy's, default -2)",
    )  # fmt: skip
    tr.add_argument(
        "--comfort-target", type=float, metavar="PCT",
        help="comfort as a constraint: minimise energy keeping this share (%%) of zone samples in band where the band "
        "applies, by a Lagrange multiplier adapted each batch (default: the reward's fixed comfort weights)",
    )  # fmt: skip
    tr.add_argument(
        "--objective", choices=("energy", "hvac", "cost", "emissions"),
        help="what the reward's energy term (and the comfort constraint) trades against: the spec's energy signals, "
        "HVAC energy, its cost or its emissions (docs/kpis.md; default: the spec's reward.objective)",
    )  # fmt: skip
    tr.add_argument(
        "--comfort-margin", type=float, default=0.5, metavar="K",
        help="with --comfort-target: the comfort cost rises over this far inside the band's edges (default 0.5)",
    )  # fmt: skip
    tr.add_argument(
        "--init-from-baseline", action="store_true",
        help="first fit the policy to the building's own controls on the training weathers (imitation), then learn; "
        "the cloned policy is saved in runs/<name>/cloned/",
    )  # fmt: skip
    tr.add_argument(
        "--gamma", type=float, default=0.99,
        help="discount factor (default 0.99, the paper's): shorter horizons learn faster where actions act quickly",
    )  # fmt: skip
    tr.add_argument("--gae-lambda", type=float, default=0.98, help="TRPO/PPO GAE lambda (default 0.98, the paper's)")
    tr.add_argument(
        "--sde-freq", type=int, default=0, metavar="STEPS",
        help="TRPO/PPO: state-dependent exploration (gSDE), each worker's noise held STEPS steps (e.g. 96, a day "
        "of 15-minute steps); default 0, independent noise every step",
    )  # fmt: skip
    tr.add_argument("--timesteps", type=int, default=1_000_000, help="total env steps (default 1e6)")
    tr.add_argument("--run-days", type=int, default=365, help="episode length in days from Jan 1 (default 365)")
    tr.add_argument(
        "--random-start", action="store_true",
        help="each episode starts on a day of the year drawn for it (from --seed), --run-days long within the year: "
        "training sees every season, not only the weeks after January 1 (BOPTEST-Gym's random start time)",
    )  # fmt: skip
    tr.add_argument("--batch-size", type=int, default=16384, help="steps per TRPO update, split across workers")
    tr.add_argument("--seed", type=int, default=0)
    tr.add_argument(
        "--seeds", metavar="S,S,...",
        help="one run per seed as a sweep's Ray Tune trials, queued by cores: runs/<run-name>/seed-<S>/ (sweep --help)",
    )  # fmt: skip
    tr.add_argument("--run-name", help="default: trpo-<weathers>-<time>")
    tr.add_argument("--resume", help="a checkpoint .zip or a run directory to continue")
    tr.add_argument(
        "--overwrite", action="store_true",
        help="reuse a taken --run-name: the old run and its TensorBoard folder move aside to <name>.old-<time>",
    )  # fmt: skip
    tr.add_argument(
        "--init-from", type=Path,
        help="start a new run from a saved model.zip's weights and observation statistics (fine-tuning); with "
        "--algorithm mbpo, from a planner run's folder (its model, and its data where it kept them)",
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
    tr.add_argument(
        "--overlap", action="store_true",
        help="TRPO/PPO: the workers collect the next batch while the learner updates on this one (data one "
        "policy old; docs/training.md). Local or --backend ray",
    )  # fmt: skip
    tr.add_argument(
        "--max-restarts", type=int, default=3,
        help="restarts in a row a worker's episode gets after EnergyPlus fails, before the run stops",
    )  # fmt: skip
    tr.add_argument("--step-timeout", type=float, default=60.0, help="seconds before a silent EnergyPlus is hung")
    tr.add_argument("--reward", type=Path, help="JSON file overriding reward constants")
    tr.add_argument(
        "--eval-every", type=int, default=0, metavar="STEPS",
        help="every STEPS env steps, run the frozen deterministic policy on --eval-weathers: evaluations.csv, "
        "TensorBoard eval/..., and the best so far kept as runs/<name>/best/model.zip (docs/training.md)",
    )  # fmt: skip
    tr.add_argument("--eval-weathers", metavar="W,...", help="default: the training weathers (never IL or VA)")
    tr.add_argument("--eval-days", type=int, metavar="N", help="evaluation episode length (default: --run-days)")
    tr.add_argument(
        "--eval-scenarios", metavar="S,...", default="start",
        help="the periods of each evaluation weather, averaged: start (--eval-days from January 1) and BOPTEST's "
        "peak_heat, typical_heat, peak_cool, typical_cool (two weeks after a week's warm-up); e.g. start,peak_cool "
        "so a controller chosen in winter must hold summer too",
    )  # fmt: skip
    tr.add_argument(
        "--target", metavar="KPI>=X,...",
        help='e.g. "in_band_pct>=99.6,energy_change_pct<=-22" (energy against the built-in controller): the step '
        "and wall time it is first met go to runs/<name>/target.json; with a target, best = met, then lowest energy",
    )  # fmt: skip
    tr.add_argument("--quiet", action="store_true", help="no progress bar")
    tr.set_defaults(func=c.cmd_train)
    return tr


def weather_options(p: argparse.ArgumentParser) -> None:
    """Weather noise and its kin: the same options for training and evaluation episodes."""
    p.add_argument(
        "--weather-noise", nargs="?", const="default", metavar="COL=SIGMA:MU:TAU,...",
        help="Ornstein-Uhlenbeck noise on each episode's weather (Sinergym's); alone: dry bulb 1:0:24 (sigma K, "
        "mu K, tau h); columns drybulb, relhum, dirnorrad, difhorrad; a value LOW..HIGH is drawn per episode",
    )  # fmt: skip
