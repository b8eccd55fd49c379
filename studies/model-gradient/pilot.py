"""Pilot: a policy network learned *through* the planner's model (issue 51), not copied from the planner's actions.

The policy (the mpc run's distilled network, its observation normalizer unchanged, so `export` and `serve` take
it as they are) is trained by gradient descent on the planner's own cost over the planner's horizon, the cost's
gradient taken through the learned ensemble (SVG(H), Heess et al. 2015; "analytic policy gradients" through a
learned model): from real states, every member rolls its own trajectory (as the planner's, PETS's TS-inf), the
policy acting at each step on the observation rebuilt from the member's predicted state (the zone temperatures and
energy parts; the outdoor dry bulb from the weather file; any other sensor held at its start), and the step's
cost is the planner's: energy x power_weight, the comfort surrogate beyond the band shrunk by the margin where the
band applies, and the members' spread. An increment beyond the planner's `max_increment` and an action outside the
data's support are penalized, since the model knows nothing there. Rounds alternate: the policy runs in EnergyPlus
on the training weathers (CA, CO, FL) at dates across the year, its states join the start states (the policy's own
states: no covariate shift), and it is trained on them again.

    .venv/bin/python studies/model-gradient/pilot.py [--rounds 4] [--out ../model-gradient]

Each round's policy is saved as <out>/round<r>/model.zip (+ vecnormalize.npz); evaluate it with `evaluate --policy`.
"""

from __future__ import annotations

import argparse
import json
import logging
import tempfile
import time
from pathlib import Path

import numpy as np
import torch as th
from tqdm import tqdm

from parallel_eplus.buildings.building import load_building
from parallel_eplus.engine.config import SimulationConfig
from parallel_eplus.evaluation.controllers import Controller
from parallel_eplus.evaluation.sweep import run_local
from parallel_eplus.learning.algorithms import ALGORITHMS
from parallel_eplus.learning.model_based.control.mpc import MPC
from parallel_eplus.learning.model_based.model.exogenous import model_schedule
from parallel_eplus.learning.model_based.students.through_model import Clock, Rollouts, Starts, train, widen
from parallel_eplus.learning.saved_models import load_model
from parallel_eplus.runs.norm_stats import read_stats
from parallel_eplus.runs.policy_files import normalization_file, stats_target

log = logging.getLogger("model-gradient")
ROOT = Path(__file__).resolve().parents[2]
RUN = ROOT / "results/model-based/datacenter-2zone/runs/datacenter-2zone-mpc-seed0"


def collect(policy_act, weathers: list[str], starts_days: list[int], days: int, workers: int, folder: Path,
            starts: Starts | None, building, spec: str | None, clock: Clock | None = None) -> list[dict]:  # fmt: skip
    """The policy (None: the building's own controls) in EnergyPlus on each (weather, start day): its episodes'
    summaries; its states into `starts`. `spec`: the planner's building (None: the paper's data center); `clock`: the
    features the policy sees after the sensors."""
    last: dict[str, np.ndarray] = {}
    initial = np.array([2 * (a.initial - a.low) / (a.high - a.low) - 1 for a in building.actions], np.float32)

    def act(obs, info):
        key = f"{info['weather']}"
        action = policy_act(obs)
        if starts is not None:
            starts.add(obs, last.get(key, initial), info["time"], info["weather"])
        last[key] = action
        return action

    controller = Controller("model-gradient", "policy", act=act) if policy_act else Controller("own", "baseline")
    clock = clock if policy_act is not None else None
    jobs = [(controller, SimulationConfig(weather=w, model=controller.model, building=spec, run_days=days,
                                          start_day=d, energyplus_csv=False, output_dir=str(folder / f"{w}-{d}"),
                                          time_features=bool(clock and clock.time),
                                          schedule_features=bool(clock and clock.schedule)))
            for w in weathers for d in starts_days]  # fmt: skip
    with tqdm(total=len(jobs) * days * building.steps_per_day, unit="step", desc="collect") as bar:
        rows, failures = run_local(jobs, workers, bar, keep_going=True)
    for f in failures:
        log.warning("episode failed: %s", f)
    return rows


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--run", type=Path, default=RUN)
    p.add_argument("--rounds", type=int, default=4)
    p.add_argument("--updates", type=int, default=600, help="gradient steps per round")
    p.add_argument("--batch", type=int, default=128)
    p.add_argument("--lr", type=float, default=3e-4)
    p.add_argument("--days", type=int, default=7, help="each collection episode's length")
    p.add_argument("--workers", type=int, default=1)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--comfort-weight", type=float, help="the comfort term's weight (default: the planner's)")
    p.add_argument("--margin", type=float, help="the band shrunk by this much, K (default: the planner's)")
    p.add_argument("--features", action="store_true", help="the policy also sees the time and IT schedule")
    p.add_argument("--out", type=Path, default=ROOT.parent / "model-gradient")
    args = p.parse_args()
    began = time.monotonic()  # each round's wall-clock from the start, loading included (to_goal.py's table)
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(name)s: %(message)s")
    logging.getLogger("parallel_eplus").setLevel(logging.WARNING)
    th.set_num_threads(1)
    th.manual_seed(args.seed)
    rng = np.random.default_rng(args.seed)

    best = args.run / "best" / "planner" / "planner.pt"  # `--eval-every`'s best, else the run's last
    mpc = MPC.load(best if best.is_file() else args.run / "planner" / "planner.pt")
    building = load_building(mpc.building)
    source = args.run / "model.zip"
    stats = read_stats(normalization_file(source))
    model = load_model(ALGORITHMS["trpo"], source, device="cpu")
    policy = model.policy
    config = json.loads((args.run / "config.json").read_text())
    schedule = model_schedule(mpc.building)  # the data centers' IT load; the offices have none
    seen = Clock(config.get("time_features", False), schedule if config.get("schedule_features") else None)
    clock = Clock(True, schedule) if args.features else seen
    if clock != seen:  # the run's policy sees the sensors alone: widened to see the clock too
        if seen.width:
            raise SystemExit(f"{args.run}: its policy already sees the clock's features; leave --features out")
        model, stats = widen(model, stats, clock, building)
        policy = model.policy
    rollouts = Rollouts(mpc, building, stats, policy, clock, args.margin)
    params = list(policy.mlp_extractor.policy_net.parameters()) + list(policy.action_net.parameters())
    opt = th.optim.Adam(params, lr=args.lr)
    weathers = ["CA", "CO", "FL"]
    starts = Starts()
    log_rows = []

    def policy_act(obs):
        with th.no_grad():
            a = rollouts.act(th.as_tensor(np.asarray(obs, np.float32)[None]))[0].numpy()
        return np.clip(a, -1, 1)

    for r in range(args.rounds + 1):
        days = sorted(rng.choice(np.arange(1, 365 - args.days, 7), size=2, replace=False).tolist())
        with tempfile.TemporaryDirectory(prefix="model-gradient-") as tmp:
            rows = collect(policy_act, weathers, [1, *days], args.days, args.workers, Path(tmp), starts, building,
                           mpc.building, clock)  # fmt: skip
            own = collect(None, weathers, [1, *days], args.days, args.workers, Path(tmp) / "own", None, building,
                          mpc.building)  # fmt: skip
        power = sum(rw["power_kw"] for rw in rows) / sum(rw["power_kw"] for rw in own) - 1
        band = float(np.mean([rw["in_band_pct"] for rw in rows]))
        names = [t.removesuffix("_temp_c") for t in building.comfort.temperatures]  # any building's zones
        zones = {z: (round(min(rw[f"{z}_temp_min"] for rw in rows), 2),
                     round(max(rw[f"{z}_temp_max"] for rw in rows), 2)) for z in names}  # fmt: skip
        log.info("round %d: zone temperatures' range %s", r, zones)
        worst = min(rw["in_band_pct"] for rw in rows)
        log.info("round %d (days %s): power %+.1f %% vs own controls, in band %.2f %% (worst episode %.2f %%); "
                 "%d start states", r, [1, *days], 100 * power, band, worst, len(starts))  # fmt: skip
        log_rows.append({"round": r, "days": [1, *days], "power_vs_own": power, "band_pct": band,
                         "worst_band_pct": worst, "starts": len(starts),
                         "wall_s": round(time.monotonic() - began, 1)})  # fmt: skip
        out = args.out / f"round{r}"
        out.mkdir(parents=True, exist_ok=True)
        model.save(out / "model.zip")
        stats.save(stats_target(out / "model.zip"))
        config.update(time_features=clock.time, schedule_features=clock.schedule is not None)
        (out / "config.json").write_text(json.dumps(config, indent=1))
        if r == args.rounds:
            break
        t0 = time.monotonic()

        def report(u, loss, parts, r=r, t0=t0):
            if u % 100 == 0 or u == args.updates - 1:
                log.info("round %d update %d: loss %.3f %s (%.0f s)", r, u, loss,
                         {k: round(v, 3) for k, v in parts.items()}, time.monotonic() - t0)  # fmt: skip

        train(rollouts, starts, opt, args.updates, args.batch, args.comfort_weight or mpc.comfort_weight, rng, report)
    (args.out / "log.json").write_text(json.dumps(log_rows, indent=1, default=str))


if __name__ == "__main__":
    main()
