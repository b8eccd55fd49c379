"""`train`'s command line (the largest option set, apart so parser.py reads subcommand by subcommand), and the
weather options it shares with `evaluate`.

Options sit in argument groups (run; building, weather and observations; algorithm; comfort and objective;
residual; workers and backend; evaluation during training) and every one has help text. `--config FILE` reads the
same options from TOML (cli/config_file.py); `--mpc`, `--sac` and `--mbpo` are `SettingsText`, which lists each
setting on `--mpc help`.
"""

from __future__ import annotations

import argparse
import importlib
import os
import shutil
import textwrap
from pathlib import Path

from parallel_eplus.cli import commands as c
from parallel_eplus.cli.config_file import ConfigFile, PresetOption, SettingsParser

ALGORITHMS = "TRPO (the paper's, default), PPO, SAC, a model-based planner (mpc) or MBPO"

EPILOG = """\
--config FILE, e.g. run.toml (keys: the long options above, with - or _; top-level keys before any [table]):

  algorithm = "mpc"
  weathers = ["CA", "CO", "FL"]        # or "CA,CO,FL"
  run-days = 14
  comfort-target = 99.6
  time-features = true                 # an on/off flag: true or false

  [mpc]                                # --mpc's settings (or: mpc = "horizon=12,consensus=true")
  horizon = 12
  consensus = true

  parallel-eplus train --config run.toml --seed 1     # the command line overrides the file

`--mpc help`, `--sac help` and `--mbpo help` list every setting with its type, default and meaning.
"""


class SettingsText(argparse.Action):
    """`--mpc NAME=VALUE,...`: kept as text (commands.py reads it by type, refusing what it cannot mean, before any
    process starts); the value `help` prints every setting of `settings` ("module:Class") and exits 0."""

    def __init__(self, option_strings, dest, settings: str, preface: str = "", **kwargs):
        self.settings, self.preface = settings, preface
        super().__init__(option_strings, dest, **kwargs)

    def __call__(self, parser, namespace, values, option_string=None):
        if values.strip().lower() == "help":
            module, _, name = self.settings.partition(":")
            width = max(80, min(shutil.get_terminal_size().columns, 120))
            print(self.preface + getattr(importlib.import_module(module), name).help_text(width))  # the help itself
            parser.exit(0)
        setattr(namespace, self.dest, values)


MPC = "parallel_eplus.learning.model_based.settings:MPCSettings"
MBPO = "parallel_eplus.learning.model_based.settings:MBPOSettings"
SAC = "parallel_eplus.learning.settings:SACSettings"


def add_train(sub) -> argparse.ArgumentParser:
    """The `train` subcommand with its options and defaults (the paper's settings)."""
    tr = sub.add_parser(
        "train", help=f"train a controller on parallel EnergyPlus workers: {ALGORITHMS}",
        description=textwrap.fill(
            f"Train a controller on parallel EnergyPlus workers: {ALGORITHMS}. The defaults are the paper's "
            "settings; every option can also come from a TOML file (--config).", 100
        ),
        epilog=EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter,
    )  # fmt: skip
    if not isinstance(tr, SettingsParser):
        raise TypeError("train's --config needs its parser built by cli/parser.py (a SettingsParser)")

    run = tr.add_argument_group("run: its name, length and where it starts")
    run.add_argument(
        "--config", action=ConfigFile, metavar="FILE",
        help="read this run's settings from a TOML file (the example below): keys are these long options, with - or "
        "_; options given on the command line override it; an unknown key is an error. The resolved settings are "
        "saved in runs/<name>/config.json like any run's",
    )  # fmt: skip
    run.add_argument(
        "--preset", action=PresetOption, metavar="NAME",
        help="a shipped preset's settings (`parallel-eplus presets` lists them) under --config's and the command "
        "line's; default: with --building and no --algorithm, the building's kind's preset (a thermostat "
        "building: thermostat-planner), else the paper's TRPO",
    )  # fmt: skip
    run.add_argument("--run-name", help="the run's folder runs/<name>/ (default: <algorithm>-<weathers>-<time>)")
    run.add_argument(
        "--timesteps", type=int, default=1_000_000,
        help="total env steps over all workers (default 1e6; with --resume: the run's own total unless given)",
    )  # fmt: skip
    run.add_argument(
        "--seed", type=int, default=0, help="random seed of the learner and the workers' draws (default 0)"
    )
    run.add_argument(
        "--seeds", metavar="S,S,...",
        help="one run per seed as a sweep's Ray Tune trials, queued by cores: runs/<run-name>/seed-<S>/ (sweep --help)",
    )  # fmt: skip
    run.add_argument(
        "--resume", help="a run folder or a checkpoint .zip to continue, with its own saved settings (config.json)"
    )
    run.add_argument(
        "--overwrite", action="store_true",
        help="reuse a taken --run-name: the old run and its TensorBoard folder move aside to <name>.old-<time>",
    )  # fmt: skip
    run.add_argument(
        "--init-from", type=Path,
        help="start a new run from a saved model.zip's weights and observation statistics (fine-tuning); with "
        "--algorithm mbpo, from a planner run's folder (its model, and its data where it kept them)",
    )  # fmt: skip
    run.add_argument(
        "--checkpoint-every", type=int, default=100_000, help="env steps between checkpoints (default 100000)"
    )
    run.add_argument(
        "--keep-episodes", type=int, default=2, help="full episode folders (step tables) kept per worker (default 2)"
    )
    run.add_argument("--quiet", action="store_true", help="no progress bar")

    bo = tr.add_argument_group("building, weather and observations")
    bo.add_argument(
        "--building", help="a building spec (TOML path or built-in name), checked first; default: the data center"
    )
    bo.add_argument(
        "--model", default="temp_fan", choices=["temp_fan", "temp"],
        help="the data center's actions: temp_fan, its zones' setpoints and fan flows (default), or temp, the "
        "setpoints alone (the fans on EnergyPlus's own control); a --building spec names its own",
    )  # fmt: skip
    bo.add_argument(
        "--weathers", default="CA",
        help="training weathers, comma-separated, e.g. CA,CO,FL, or a --building spec's own names (default CA)",
    )  # fmt: skip
    bo.add_argument("--run-days", type=int, default=365, help="episode length in days from Jan 1 (default 365)")
    bo.add_argument(
        "--random-start", action="store_true",
        help="each episode starts on a day of the year drawn for it (from --seed), --run-days long within the year: "
        "training sees every season, not only the weeks after January 1 (BOPTEST-Gym's random start time)",
    )  # fmt: skip
    weather_options(bo)
    bo.add_argument(
        "--time-features", action="store_true",
        help="add hour and day of week (sine/cosine) to the paper's six observations",
    )  # fmt: skip
    bo.add_argument(
        "--schedule-features", action="store_true",
        help="add the IT-load schedule: the coming step's load, its last and next change, and how far away",
    )  # fmt: skip
    bo.add_argument(
        "--forecast", type=int, default=0, metavar="HOURS",
        help="add the outdoor temperature's next HOURS hours (from the episode's weather file) to the observation",
    )  # fmt: skip
    bo.add_argument("--forecast-error", choices=["low", "medium", "high"],
                    help="with --forecast: BOPTEST's AR(1) forecast error at this level (default: exact)")  # fmt: skip

    al = tr.add_argument_group("algorithm")
    al.add_argument(
        "--algorithm", default="trpo", choices=["trpo", "ppo", "sac", "mpc", "mbpo"],
        help="trpo: the paper's (sb3-contrib), default; ppo: Stable-Baselines3's, same network and discounting; "
        "sac: Stable-Baselines3's off-policy SAC (--sac; --batch-size is unused); "
        "mpc: learn a model of the building and plan on it, then distil the planner (--mpc; docs/model-based.md); "
        "mbpo: SAC on real steps and short rollouts of that model, comfort as a constraint (--init-from an mpc run)",
    )  # fmt: skip
    al.add_argument(
        "--mpc", action=SettingsText, settings=MPC, metavar="NAME=VALUE,...|help",
        help="with --algorithm mpc (and mbpo, for its model): the model's and the planner's settings, e.g. "
        "horizon=12,consensus=true; `--mpc help` lists every one with its type, default and meaning",
    )  # fmt: skip
    al.add_argument(
        "--sac", action=SettingsText, settings=SAC, metavar="NAME=VALUE,...|help",
        help="with --algorithm sac or mbpo: SAC's settings, e.g. ent_coef=0.05,net_arch=64x64; `--sac help` lists them",
    )  # fmt: skip
    al.add_argument(
        "--mbpo", action=SettingsText, settings=MBPO, metavar="NAME=VALUE,...|help",
        help="with --algorithm mbpo: its rollouts' settings, e.g. rollout_length=2; `--mbpo help` lists them",
    )  # fmt: skip
    al.add_argument(
        "--batch-size", type=int, default=16384,
        help="TRPO/PPO: env steps per update, split evenly across the workers (default 16384, the paper's)",
    )  # fmt: skip
    al.add_argument(
        "--gamma", type=float, default=0.99,
        help="discount factor (default 0.99, the paper's): shorter horizons learn faster where actions act quickly",
    )  # fmt: skip
    al.add_argument("--gae-lambda", type=float, default=0.98, help="TRPO/PPO GAE lambda (default 0.98, the paper's)")
    al.add_argument(
        "--sde-freq", type=int, default=0, metavar="STEPS",
        help="TRPO/PPO: state-dependent exploration (gSDE), each worker's noise held STEPS steps (e.g. 96, a day "
        "of 15-minute steps); default 0, independent noise every step",
    )  # fmt: skip
    al.add_argument(
        "--log-std-init", type=float, default=0.0,
        help="the new policy's log standard deviation (default 0, the paper's; --init-from keeps the saved one; "
        "with --init-from-baseline the cloned policy's, default -2)",
    )  # fmt: skip
    al.add_argument(
        "--init-from-baseline", action="store_true",
        help="first fit the policy to the building's own controls on the training weathers (imitation), then learn; "
        "the cloned policy is saved in runs/<name>/cloned/",
    )  # fmt: skip

    co = tr.add_argument_group("comfort and objective")
    co.add_argument(
        "--comfort-target", type=float, metavar="PCT",
        help="comfort as a constraint: minimise energy keeping this share (%%) of zone samples in band where the band "
        "applies, by a Lagrange multiplier adapted each batch (default: the reward's fixed comfort weights)",
    )  # fmt: skip
    co.add_argument(
        "--comfort-margin", type=float, default=0.5, metavar="K",
        help="with --comfort-target: the comfort cost rises over this far inside the band's edges (default 0.5)",
    )  # fmt: skip
    co.add_argument(
        "--objective", choices=("energy", "hvac", "cost", "emissions"),
        help="what the reward's energy term (and the comfort constraint) trades against: the spec's energy signals, "
        "HVAC energy, its cost or its emissions (docs/kpis.md; default: the spec's reward.objective)",
    )  # fmt: skip
    co.add_argument("--reward", type=Path, help="a JSON file overriding the reward's constants (docs/training.md)")

    rs = tr.add_argument_group("residual: correcting a rule-based controller")
    rs.add_argument(
        "--residual", type=float, default=0.0, metavar="SCALE",
        help="the policy corrects the rule-based controller's action by up to SCALE (e.g. 0.2) instead of acting "
        "alone; with --residual-space builtin, the building's own setpoint schedules",
    )  # fmt: skip
    rs.add_argument(
        "--residual-space", default="action", choices=["action", "demand", "builtin"],
        help="with --residual: correct each normalized action (default) or each zone's flow demand (SCALE in kg/s) "
        "of the rule-based controller, or (builtin) the building's own thermostat schedules by up to SCALE of half "
        "each action's range: a zero correction runs the building's own controls exactly",
    )  # fmt: skip
    rs.add_argument("--rbc-target", type=float, help="with --residual: the rule-based controller's zone target, C")

    wb = tr.add_argument_group("workers and backend")
    wb.add_argument("--workers", type=int, default=os.cpu_count() or 1, help="EnergyPlus processes (default: cores)")
    wb.add_argument(
        "--backend", default="local", choices=["local", "ray"],
        help="local: the workers are this machine's processes (default); ray: Ray actors, on --ray-address's cluster "
        "or a local Ray",
    )  # fmt: skip
    wb.add_argument("--ray-address", help="an existing Ray cluster (default: start Ray locally)")
    wb.add_argument("--workers-per-actor", type=int, help="Ray: EnergyPlus workers hosted by each actor")
    wb.add_argument(
        "--lockstep", action="store_true",
        help="step all workers together (a seed then fixes the run bit for bit). Default: each "
        "local worker gets its next action as soon as its observation arrives",
    )  # fmt: skip
    wb.add_argument(
        "--overlap", action="store_true",
        help="TRPO/PPO: the workers collect the next batch while the learner updates on this one (data one "
        "policy old; docs/training.md). Local or --backend ray",
    )  # fmt: skip
    wb.add_argument(
        "--max-restarts", type=int, default=3,
        help="restarts in a row a worker's episode gets after EnergyPlus fails, before the run stops",
    )  # fmt: skip
    wb.add_argument("--step-timeout", type=float, default=60.0, help="seconds before a silent EnergyPlus is hung")

    ev = tr.add_argument_group("evaluation during training")
    ev.add_argument(
        "--eval-every", type=int, default=0, metavar="STEPS",
        help="every STEPS env steps, run the frozen deterministic policy on --eval-weathers: evaluations.csv, "
        "TensorBoard eval/..., and the best so far kept as runs/<name>/best/model.zip (docs/training.md)",
    )  # fmt: skip
    ev.add_argument("--eval-weathers", metavar="W,...", help="default: the training weathers (never IL or VA)")
    ev.add_argument("--eval-days", type=int, metavar="N", help="evaluation episode length (default: --run-days)")
    ev.add_argument(
        "--eval-scenarios", metavar="S,...", default="start",
        help="the periods of each evaluation weather, averaged: start (--eval-days from January 1) and BOPTEST's "
        "peak_heat, typical_heat, peak_cool, typical_cool (two weeks after a week's warm-up); e.g. start,peak_cool "
        "so a controller chosen in winter must hold summer too",
    )  # fmt: skip
    ev.add_argument(
        "--target", metavar="KPI>=X,...",
        help='e.g. "in_band_pct>=99.6,energy_change_pct<=-22" (energy against the built-in controller): the step '
        "and wall time it is first met go to runs/<name>/target.json; with a target, best = met, then lowest energy",
    )  # fmt: skip
    tr.set_defaults(func=c.cmd_train)
    return tr


def weather_options(p) -> None:
    """Weather noise and its kin: the same options for training and evaluation episodes (`p`: a parser or one of
    its argument groups)."""
    p.add_argument(
        "--weather-noise", nargs="?", const="default", metavar="COL=SIGMA:MU:TAU,...",
        help="Ornstein-Uhlenbeck noise on each episode's weather (Sinergym's); alone: dry bulb 1:0:24 (sigma K, "
        "mu K, tau h); columns drybulb, relhum, dirnorrad, difhorrad; a value LOW..HIGH is drawn per episode",
    )  # fmt: skip
