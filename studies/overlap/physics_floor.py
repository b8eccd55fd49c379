"""Training against the physics' own time: fresh TRPO runs, sequential and with --overlap, each followed by raw
EnergyPlus under every action it took (`bench --replay-run`, the same workers at a time, no pipes, no learner).

The rounds alternate (sequential, its replay, overlapped, its replay, ...) so the machine's drift weighs on all
alike; each phase records how busy the machine was (load average; every core's busy share from /proc/stat, and
the part of it that was ours). Episodes end exactly at the last step (full batches of whole episodes), so the
replay holds every step trained on.

    PYTHONPATH=. .venv/bin/python studies/overlap/physics_floor.py --out results/overlap/physics_floor --repeats 2
"""

from __future__ import annotations

import argparse
import json
import logging
import os
import resource
import statistics
import tempfile
import time
from pathlib import Path

from parallel_eplus.bench import replay_run
from parallel_eplus.training.callbacks import UpdateTimer
from parallel_eplus.training.config import TrainConfig
from parallel_eplus.training.train import train


def _cpu() -> tuple[float, float, float]:
    """(machine busy core-seconds, machine total core-seconds, ours: this process and its reaped children)."""
    fields = [float(x) for x in Path("/proc/stat").read_text().splitlines()[0].split()[1:]]
    tick = os.sysconf("SC_CLK_TCK")
    idle = fields[3] + fields[4]
    t = os.times()
    return (sum(fields) - idle) / tick, sum(fields) / tick, t.user + t.system + t.children_user + t.children_system


class Busy:
    """How busy the machine was over a phase."""

    def __enter__(self):
        self.load0, self.cpu0, self.t0 = os.getloadavg()[0], _cpu(), time.perf_counter()
        self.own0 = resource.getrusage(resource.RUSAGE_SELF)
        return self

    def __exit__(self, *exc):
        busy, total, ours = (b - a for a, b in zip(self.cpu0, _cpu(), strict=True))
        self.wall_s = time.perf_counter() - self.t0
        own = resource.getrusage(resource.RUSAGE_SELF)  # this process alone: the learner, in a training phase
        own_s = own.ru_utime + own.ru_stime - self.own0.ru_utime - self.own0.ru_stime
        self.figures = {"load_start": self.load0, "load_end": os.getloadavg()[0], "machine_busy": busy / total,
                        "ours_of_machine": ours / total, "others_of_machine": max(busy - ours, 0) / total,
                        "this_process_cpu_s": own_s, "children_cpu_s": ours - own_s}  # fmt: skip


def one_round(mode: str, k: int, root: Path, args: argparse.Namespace) -> dict:
    name = f"{mode}-{k}"
    cfg = TrainConfig(
        workers=args.workers, weathers=args.weathers.split(","), run_days=args.run_days, timesteps=args.timesteps,
        batch_size=args.batch_size, seed=0, run_name=name, runs_dir=str(root / "runs"),
        tensorboard_dir=str(root / "tb"), checkpoint_every=10**9, keep_episodes=10**4, overlap=mode == "overlap",
    )  # fmt: skip
    timer = UpdateTimer()
    with Busy() as trained:
        train(cfg, progress=False, timer=timer)
    with Busy() as replayed, tempfile.TemporaryDirectory(dir=root) as tmp:
        raw = replay_run(root / "runs" / name, args.workers, Path(tmp), progress=False)
    assert raw["steps"] == timer.learn_steps, (raw["steps"], timer.learn_steps)  # every step trained on, replayed
    train_rate = timer.learn_steps / timer.learn_s
    return {
        "mode": mode, "round": k, "steps": timer.learn_steps, "learn_s": timer.learn_s, "train_steps_per_s": train_rate,
        "updates_s": sum(timer.updates), "raw_wall_s": raw["raw_wall_s"], "raw_steps_per_s": raw["raw_steps_per_s"],
        "train_over_raw": train_rate / raw["raw_steps_per_s"],
        "train_busy": trained.figures, "replay_busy": replayed.figures,
    }  # fmt: skip


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--out", type=Path, required=True)
    p.add_argument("--workers", type=int, default=2)
    p.add_argument("--weathers", default="CA,CO,FL")
    p.add_argument("--run-days", type=int, default=256, help="256 days: 24,576 steps, three batches per worker")
    p.add_argument("--batch-size", type=int, default=16384)
    p.add_argument("--timesteps", type=int, default=98304, help="whole episodes on every worker")
    p.add_argument("--repeats", type=int, default=2)
    p.add_argument("--modes", default="sequential,overlap")
    p.add_argument("--workdir", type=Path, help="where runs go (default: a temporary folder)")
    args = p.parse_args()
    logging.basicConfig(level=logging.WARNING, format="%(asctime)s %(levelname)s %(message)s")
    args.out.mkdir(parents=True, exist_ok=True)
    rows = []
    with tempfile.TemporaryDirectory(prefix="physics-floor-", dir=args.workdir) as tmp:
        for k in range(args.repeats):
            for mode in args.modes.split(","):
                rows.append(one_round(mode, k, Path(tmp), args))
                print(json.dumps(rows[-1]), flush=True)
                (args.out / "physics_floor.json").write_text(json.dumps({"config": vars(args) | {"out": str(args.out),
                                                                        "workdir": str(args.workdir)}, "runs": rows},
                                                                       indent=2))  # fmt: skip
    lines = [
        f"{args.workers} workers, {args.weathers}, {args.run_days}-day episodes, {args.timesteps} steps, batch "
        f"{args.batch_size}, seed 0; rounds alternate",
        "",
        "| round | mode | train steps/s | raw EnergyPlus steps/s (same actions) | train / raw | updates, s | "
        "learner CPU, s | EnergyPlus CPU, s: train · replay | machine busy (ours / others), train · replay | "
        "load avg |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        tb, rb = r["train_busy"], r["replay_busy"]
        lines.append(f"| {r['round'] + 1} | {r['mode']} | {r['train_steps_per_s']:.0f} | {r['raw_steps_per_s']:.0f} | "
                     f"**{r['train_over_raw']:.2f}** | {r['updates_s']:.1f} | {tb['this_process_cpu_s']:.1f} | "
                     f"{tb['children_cpu_s']:.1f} · {rb['children_cpu_s']:.1f} | "
                     f"{tb['machine_busy']:.0%} ({tb['ours_of_machine']:.0%} / {tb['others_of_machine']:.0%}) · "
                     f"{rb['machine_busy']:.0%} ({rb['ours_of_machine']:.0%} / {rb['others_of_machine']:.0%}) | "
                     f"{tb['load_start']:.1f} |")  # fmt: skip
    for mode in args.modes.split(","):
        ratios = [r["train_over_raw"] for r in rows if r["mode"] == mode]
        lines.append(
            f"\n{mode}: train / raw median {statistics.median(ratios):.2f} ({', '.join(f'{x:.2f}' for x in ratios)})"
        )
    text = "\n".join(lines) + "\n"
    (args.out / "physics_floor.md").write_text(text)
    print(text)


if __name__ == "__main__":
    main()
