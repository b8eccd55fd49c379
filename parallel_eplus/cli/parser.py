"""The command line's arguments: every subcommand, option and default in one place."""

from __future__ import annotations

import argparse
import os
from importlib.metadata import PackageNotFoundError, version
from pathlib import Path

from parallel_eplus.cli import commands as c
from parallel_eplus.cli import deploy, many_runs
from parallel_eplus.cli.boptest import add_boptest
from parallel_eplus.cli.config_file import PresetOption, SettingsParser
from parallel_eplus.cli.evaluate import cmd_evaluate
from parallel_eplus.cli.optimize import add_optimize
from parallel_eplus.cli.presets import cmd_presets
from parallel_eplus.cli.train_parser import MPC, SettingsText, add_train, weather_options


def installed_version() -> str:
    """The installed distribution's version (pyproject.toml's, through the package metadata: one source of truth)."""
    try:
        return version("parallel-eplus")
    except PackageNotFoundError:  # imported from a source tree that was never installed
        return "unknown (not installed)"


DESCRIPTION = "Train and evaluate RL controllers for buildings against parallel EnergyPlus simulations."
# What `evaluate --planner help` and `bench --planner-options help` print before the planner's settings.
PLANNER_OPTIONS = (
    "forecast=perfect|low|medium|high: the weather forecast the planner reads (the file, or it with\n"
    "    BOPTEST's forecast errors; default perfect)\n"
    "seed=N: the planner's sampler's seed (default: its own)\n"
    "and any of its settings, overriding the saved planner's:\n\n"
)


def build_parser() -> argparse.ArgumentParser:
    """Every subcommand with its options and defaults (a SettingsParser: `train --config FILE` reads a TOML file)."""
    parser = SettingsParser(prog="parallel-eplus", description=DESCRIPTION)
    parser.add_argument("-v", "--verbose", action="store_true", help="debug logging")
    parser.add_argument("--version", action="version", version=f"%(prog)s {installed_version()}")
    sub = parser.add_subparsers(dest="command", required=True)

    sim = sub.add_parser("simulate", help="run one episode and print the paper's episode statistics")
    sim.add_argument("--weather", default="CA", help="CA, CO, FL, IL, VA or a path to an .epw (default CA)")
    sim.add_argument("--days", type=int, default=7, help="run period length from Jan 1 (default 7)")
    sim.add_argument(
        "--model", default="temp_fan", choices=["temp_fan", "temp"],
        help="the data center's actions: setpoints and fan flows (temp_fan, default) or setpoints alone (temp)",
    )  # fmt: skip
    sim.add_argument("--building", help="a building spec (TOML path or built-in name); default: the data center")
    sim.add_argument("--policy", default="constant", choices=["constant", "random"],
                     help="constant: --action every step (default); random: uniform random actions")  # fmt: skip
    sim.add_argument("--action", help="the constant action in [-1, 1], comma-separated (default all 0)")
    sim.add_argument("--output-dir", type=Path, help="keep the episode records here")
    sim.add_argument("--reward", type=Path, help="JSON file overriding reward constants")
    sim.add_argument("--seed", type=int, default=0, help="seed of the random policy and the episode (default 0)")
    sim.add_argument("--quiet", action="store_true", help="no progress bar")
    bn = sim.add_argument_group("as a BACnet/IP device (docs/bacnet.md; needs the [bacnet] extra)")
    bn.add_argument("--bacnet", metavar="ADDRESS", help="serve the episode as a BACnet/IP device on host[/mask][:port]"
                    ": sensors as analog inputs, setpoints as commandable analog values")  # fmt: skip
    bn.add_argument("--step-seconds", type=float, help="a control step every this many seconds (default: lockstep, "
                    "a step each time a client writes the `advance` point)")  # fmt: skip
    bn.add_argument("--point-map", type=Path, default=Path("points.toml"), help="where to write the device's points")
    bn.add_argument("--device-id", type=int, default=599, help="the device's BACnet instance (default 599)")
    bn.add_argument("--warmup", choices=["initial", "builtin"], default="initial",
                    help="EnergyPlus warms up holding the initial action (as training does) or under its own controls",
                    )  # fmt: skip
    bn.add_argument("--watchdog", type=int, default=1, metavar="STEPS",
                    help="relinquish a supervisor that missed this many steps (default 1)")  # fmt: skip
    sim.set_defaults(func=c.cmd_simulate)

    add_train(sub)

    add_optimize(sub)
    add_boptest(sub)

    ps = sub.add_parser("presets", help="the shipped presets: settings that earned their place, with their reasons")
    ps.add_argument("name", nargs="?", help="show this preset with every setting, its reason and its evidence")
    ps.set_defaults(func=cmd_presets, needs=None)

    sw = sub.add_parser("sweep", help="trainings over seeds and a grid or search of train settings, as Ray Tune trials")
    sw.add_argument("spec", type=Path, metavar="SPEC.toml", help="the sweep (docs/training.md); re-run it to continue")
    sw.add_argument("--ray-address", help="a Ray cluster to run the trials on (default: start Ray locally)")
    sw.add_argument("--overwrite", action="store_true", help="move a sweep of the same name aside and start afresh")
    sw.set_defaults(func=many_runs.cmd_sweep)

    ev = sub.add_parser("evaluate", help="controllers x weathers sweep: the paper's table and figures")
    ev.add_argument("--policy", action="append", help="a trained model.zip (or run dir); PATH=LABEL sets the label")
    ev.add_argument(
        "--planner", metavar="forecast=perfect|low|medium|high,NAME=VALUE,...|help", action=SettingsText,
        settings=MPC, preface=PLANNER_OPTIONS,
        help="how each --policy that is a planner (runs/<name>/planner) runs: its weather forecast (the file, or it "
        "with BOPTEST's forecast errors) and planner settings overriding its own, e.g. candidates=128; "
        "`--planner help` lists them",
    )  # fmt: skip
    ev.add_argument(
        "--oracle", nargs="?", const="", metavar="NAME=VALUE,...|help", action=SettingsText,
        settings="parallel_eplus.learning.oracle.settings:OracleSettings",
        help="include the oracle: at each decision it plays candidate action sequences in forks of the running "
        "EnergyPlus and applies the best (docs/oracle.md); settings e.g. horizon_h=24,candidates=24; "
        "`--oracle help` lists them",
    )  # fmt: skip
    ev.add_argument(
        "--preset", action=PresetOption, metavar="NAME",
        help="a shipped preset's evaluation settings (e.g. thermostat-planner: --planner band_thermostats=baseline) "
        "under the command line's; `parallel-eplus presets` lists them",
    )  # fmt: skip
    ev.add_argument("--baseline", action="store_true", help="include EnergyPlus's built-in controller")
    ev.add_argument(
        "--rbc", nargs="?", const=True, default=False, metavar="MODULE:CLASS",
        help="include the rule-based controller: the spec's `controller`, or the class named here (e.g. "
        "parallel_eplus.buildings.rules.precool:PreCool, pre-cooling ahead of the tariff's peak)",
    )  # fmt: skip
    ev.add_argument(
        "--rbc-targets", metavar="C,C,...",
        help="the rule-based controller once per zone target (°C), e.g. 22.7,23.5: what the reward pays for each",
    )  # fmt: skip
    ev.add_argument(
        "--weathers", default="CA,CO,FL,IL,VA",
        help="short names or .epw paths; 'all': the 16 files EnergyPlus ships (docs/weather.md)",
    )  # fmt: skip
    weather_options(ev)
    ev.add_argument(
        "--noisy-years", type=int, default=3, metavar="N",
        help="with --weather-noise: N noisy years (seeds 0..N-1) per weather; mean and interval",
    )  # fmt: skip
    ev.add_argument(
        "--building", help="a building spec (TOML path or built-in name), checked first; default: the data center"
    )
    ev.add_argument("--run-days", type=int, default=365, help="episode length in days from Jan 1 (default 365)")
    ev.add_argument(
        "--scenario", default="year", choices=("year", "peak_heat", "typical_heat", "peak_cool", "typical_cool"),
        help="BOPTEST's test periods: two weeks around each weather's peak or typical heating or cooling day of the "
        "built-in controls, after a one-week warm-up (evaluation/scenarios.py); default: the year (--run-days)",
    )  # fmt: skip
    ev.add_argument("--workers", type=int, default=os.cpu_count() or 1, help="episodes run at once")
    ev.add_argument("--out", type=Path, default=Path("results") / "latest",
                    help="folder for the table, figures and episodes (default results/latest)")  # fmt: skip
    ev.add_argument(
        "--resume", action="store_true",
        help="keep the episodes an interrupted run of this command finished in --out; run only the others",
    )  # fmt: skip
    ev.add_argument("--histogram", help="CONTROLLER,WEATHER for the West-zone histogram (default: last, VA)")
    ev.add_argument("--reward", type=Path, help="JSON file overriding reward constants")
    ev.add_argument(
        "--online", action="store_true",
        help="also the paper's protocol: each --policy (TRPO/PPO) keeps learning, stochastic, on each weather for "
        "one episode (a copy; the saved model is untouched); rows labelled '..., online'",
    )  # fmt: skip
    ev.add_argument("--online-batch", type=int, help="with --online: steps per update (default: the run's own)")
    ev.add_argument("--backend", default="local", choices=["local", "ray"],
                    help="ray: each episode is a Ray task on --ray-address's cluster (or a local Ray)")  # fmt: skip
    ev.add_argument("--ray-address", help="an existing Ray cluster (default: start Ray locally)")
    ev.add_argument("--quiet", action="store_true", help="no progress bar")
    ev.add_argument(
        "--controller-url", action="append", metavar="URL",
        help="a controller served by `parallel-eplus serve` (e.g. http://127.0.0.1:8000): each step goes over HTTP",
    )  # fmt: skip
    ev.add_argument("--token-file", type=Path, metavar="FILE", help="with --controller-url: the server's bearer "
                    "token on the file's first line (default: $PARALLEL_EPLUS_TOKEN); never shown")  # fmt: skip
    ev.set_defaults(func=cmd_evaluate)
    deploy.add_commands(sub)

    be = sub.add_parser("bench", help="measure our overhead against raw EnergyPlus on this machine")
    be.add_argument("--weather", default="CA", help="a short name (the spec's, or CA, CO, FL, IL, VA) or an .epw")
    be.add_argument(
        "--building", help="a building spec (TOML path or built-in name), checked first; default: the data center"
    )
    be.add_argument("--days", type=int, default=365, help="period for the raw and env runs (default a year)")
    be.add_argument("--train-steps", type=int, default=16384, help="env steps of TRPO learn (default one batch)")
    be.add_argument(
        "--vector-steps", type=int, help="vector steps per worker (default: the same simulated days as training)"
    )
    be.add_argument("--workers", type=int, default=os.cpu_count() or 1, help="EnergyPlus processes (default: cores)")
    be.add_argument("--repeats", type=int, default=3, help="repetitions; medians are reported")
    be.add_argument("--out", type=Path, default=Path("results") / "bench.json",
                    help="where to write the results (default results/bench.json)")  # fmt: skip
    be.add_argument("--no-ray", action="store_true", help="skip the Ray backend's row (a local Ray's training rate)")
    be.add_argument("--short", action="store_true", help="also short episodes: consecutive ones against EnergyPlus "
                    "alone, reset latency, TRPO steps/s at 1, 7, 14 and 365-day episodes (docs/speed.md)")  # fmt: skip
    be.add_argument("--boptest", action="store_true", help="also BOPTEST's API: what each POST /advance to "
                    "`parallel-eplus boptest` adds over EnergyPlus stepped alone, ms per step (p50, p99), over --days "
                    "(docs/boptest.md)")  # fmt: skip
    be.add_argument(
        "--planner", type=Path, metavar="RUN",
        help="instead: a model-based run's planner, ms per decision beside its distilled policy network's",
    )  # fmt: skip
    be.add_argument(
        "--planner-options", metavar="NAME=VALUE,...|help", action=SettingsText, settings=MPC,
        preface=PLANNER_OPTIONS, help="with --planner: as evaluate --planner (`help` lists them)",
    )  # fmt: skip
    be.add_argument(
        "--served", action="store_true",
        help="with --planner: also export it, serve it over loopback and run it in closed loop through evaluate's "
        "client: each POST /act's round trip (p50, p99) and the server's CPU per decision, with the load average",
    )  # fmt: skip
    be.add_argument(
        "--replay-run", type=Path, metavar="RUN_DIR",
        help="instead: replay a training run's actions in raw EnergyPlus (needs its step tables: --keep-episodes)",
    )  # fmt: skip
    be.set_defaults(func=c.cmd_bench)

    bd = sub.add_parser("building", help="building specs: start one from a model (init), check one against it (check)")
    bsub = bd.add_subparsers(dest="building_command", required=True)
    bi = bsub.add_parser("init", help="run MODEL.idf briefly and write a commented starter spec")
    bi.add_argument("idf", type=Path, metavar="MODEL.idf", help="the EnergyPlus model to start a spec from")
    bi.add_argument("--weather", default="CA", help="CA, CO, FL, IL, VA or an .epw path, for the run and the spec")
    bi.add_argument("-o", "--output", type=Path, help="the spec to write (default: MODEL.toml beside the model)")
    bi.add_argument("--name", help="the building's name in the spec (default: from the file name)")
    bi.set_defaults(func=c.cmd_building_init)
    bc = bsub.add_parser("check", help="resolve every variable, meter and actuator of SPEC against its model")
    bc.add_argument("spec", metavar="SPEC.toml", help="a spec file or a built-in spec's name")
    bc.add_argument("--weather", help="short name or .epw for the check's run (default: the spec's first)")
    bc.add_argument("--no-cache", action="store_true", help="run EnergyPlus even if this spec passed before")
    bc.set_defaults(func=c.cmd_building_check)

    pl = sub.add_parser(
        "plot", help="RUN_DIR: convergence; EPISODE_DIR: its time series; SWEEP_DIR: figures from results.csv"
    )
    pl.add_argument("path", type=Path, help="a run, episode or sweep folder")
    pl.set_defaults(func=c.cmd_plot)

    ru = sub.add_parser("runs", help="list the runs under a folder: state, progress, latest results; show or stop one")
    ru.add_argument("--dir", type=Path, default=Path("runs"), help="the runs folder (default runs)")
    rsub = ru.add_subparsers(dest="runs_command")
    rs = rsub.add_parser("show", help="one run's progress, latest episode per weather and settings")
    rt = rsub.add_parser("stop", help="stop a running training as Ctrl-C does: a checkpoint, then nothing left")
    rt.add_argument("--timeout", type=float, default=300.0, help="seconds to wait for it to exit (default 300)")
    for p in (rs, rt):
        p.add_argument("name", help="as `runs` lists it, or a run folder")
        p.add_argument("--dir", type=Path, default=argparse.SUPPRESS, help="the runs folder (default runs)")
    ru.set_defaults(func=many_runs.cmd_runs)

    cl = sub.add_parser(
        "clean", help="remove pipe directories left by killed runs; list (or --kill) their leftover EnergyPlus"
    )
    cl.add_argument("--dry-run", action="store_true", help="only list the stale pipe directories")
    cl.add_argument("--kill", action="store_true", help="also stop leftover EnergyPlus processes (SIGKILL)")
    cl.set_defaults(func=c.cmd_clean, needs=None)
    return parser
