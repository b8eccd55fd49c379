"""`parallel-eplus evaluate`: the controllers a user names, checked before anything runs, swept over weathers (or a
test scenario's periods), then the tables and figures (evaluation/), with every failed episode reported beside them.
"""

from __future__ import annotations

import argparse


def _temperatures(text: str, flag: str) -> list[float]:
    try:
        return [float(t) for t in text.split(",")]
    except ValueError:
        raise ValueError(f"{flag} takes zone temperatures in °C, comma-separated (e.g. 22.7,23.5): {text!r}") from None


def cmd_evaluate(args: argparse.Namespace) -> int:
    from parallel_eplus import io
    from parallel_eplus.buildings.building import load_building
    from parallel_eplus.buildings.scoring.reward import RewardConfig
    from parallel_eplus.buildings.weather.files import parse_weathers
    from parallel_eplus.errors import EnergyPlusError
    from parallel_eplus.evaluation.controllers import (
        BASELINE_LABEL,
        RBC_LABEL,
        Controller,
        check_same_controllers,
        http_controller,
        policy_controllers,
    )
    from parallel_eplus.evaluation.results import failures_markdown, write_results
    from parallel_eplus.evaluation.sweep import run_sweep

    # bad input fails here, before anything runs (a spec's own short names: in run_sweep, against the spec)
    weathers = (
        [w.strip() for w in args.weathers.split(",") if w.strip()] if args.building else parse_weathers(args.weathers)
    )
    if args.building and args.weathers.strip().lower() == "all":
        weathers = parse_weathers("all")
    if args.workers < 1 or not 1 <= args.run_days <= 365:
        raise ValueError("--workers must be at least 1 and --run-days within 1..365")
    building = load_building(args.building)  # resolved once: every check, controller and episode below reads it
    controllers = []
    if args.baseline:
        controllers.append(Controller(BASELINE_LABEL, "baseline"))
    if isinstance(args.rbc, str):  # a class named on the command line instead of the spec's `controller`
        building.controller_class(args.rbc)  # a name that does not import fails here
        controllers.append(Controller(f"{RBC_LABEL} ({args.rbc.rpartition(':')[2]})", "rbc", rule=args.rbc))
    elif args.rbc:
        controllers.append(Controller(RBC_LABEL, "rbc"))
    if args.rbc and building.named and building.spec.controller_settings:
        controllers[-1].make(building)  # the spec's settings for its rule: a wrong one fails here
    for target in _temperatures(args.rbc_targets, "--rbc-targets") if args.rbc_targets else []:
        controllers.append(Controller(f"{RBC_LABEL} ({target:g} °C)", "rbc", rbc_target_c=target))
    for path in args.policy or []:  # a model-based run's planner, else a policy or a folder of runs (seeds)
        from parallel_eplus.learning.model_based.control.saved_planner import planner_controller  # torch: only here

        planner = planner_controller(path, args.planner)
        controllers += [planner] if planner else policy_controllers(path)
    if getattr(args, "oracle", None) is not None:  # plans on EnergyPlus itself (learning/oracle/)
        from parallel_eplus.learning.oracle.controller import oracle_controller

        controllers.append(oracle_controller(args.oracle))
    if args.controller_url:
        from parallel_eplus.evaluation.http_controller import client_token

        token = client_token(getattr(args, "token_file", None))  # --token-file, else $PARALLEL_EPLUS_TOKEN
        served = [http_controller(url, token) for url in args.controller_url]
        check_same_controllers(controllers, served)  # --policy beside the served controller: the same one
        controllers += served
    if not controllers:
        raise ValueError(
            "nothing to evaluate: give --baseline, --rbc, --rbc-targets, --policy PATH, --oracle and/or "
            "--controller-url URL"
        )
    histogram = tuple(args.histogram.rsplit(",", 1)) if args.histogram else None  # labels may hold commas
    periods = None
    if args.scenario != "year":  # each weather's two weeks, from a year of the built-in controls (kept in --out)
        from parallel_eplus.evaluation.scenarios import find_periods

        periods = find_periods(args.scenario, weathers, building, args.out, args.workers, not args.quiet)
    df = run_sweep(
        controllers, weathers, args.run_days, args.workers, args.out, RewardConfig.from_any(args.reward),
        not args.quiet, building, args.backend, args.ray_address, keep_going=True, periods=periods,
        weather_noise=args.weather_noise, noisy_years=args.noisy_years, resume=args.resume,
    )  # fmt: skip
    failures = df.attrs.get("failures", [])
    if df.empty:
        raise EnergyPlusError("no episode finished:\n" + failures_markdown(failures).strip())
    if args.online:
        import pandas as pd

        from parallel_eplus.experiments.online import run_online

        policies = [c for c in controllers if c.kind == "policy"]
        if not policies:
            raise ValueError("--online needs --policy: only a learning policy can keep learning")
        online = run_online(policies, weathers, args.run_days, args.workers, args.out, args.online_batch)
        df = pd.concat([df, online], ignore_index=True)
    files = write_results(df, args.out, histogram)
    if periods:  # the dates each weather's figures count, beside them
        from parallel_eplus.evaluation.scenarios import periods_markdown

        io.write_text(args.out / "results.md", (args.out / "results.md").read_text() + periods_markdown(periods))
    if failures:  # the finished episodes are written; the report says which did not and why
        io.write_text(args.out / "results.md", (args.out / "results.md").read_text() + failures_markdown(failures))
    print((args.out / "results.md").read_text())
    print("written: " + ", ".join(str(f) for f in files))
    return 1 if failures else 0
