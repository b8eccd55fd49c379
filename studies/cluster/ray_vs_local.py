"""The same training through Ray and locally, side by side: steps/s, round trips and the learner's idle share.

Runs alternate (local, Ray, local, Ray, ...) so the machine's drift hits both alike; each run is a fresh
`train` with the same seed, workers, batch and episodes. Ray joins the cluster at --address (started as
docs/cluster.md shows; export RAY_AUTH_MODE=token and RAY_AUTH_TOKEN_PATH first), or a local Ray without it.

    PYTHONPATH=. .venv/bin/python studies/cluster/ray_vs_local.py --address 10.200.0.1:6379 --out results/cluster
"""

from __future__ import annotations

import argparse
import json
import logging
import os
import statistics
import tempfile
import threading
import time
from pathlib import Path

from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

from parallel_eplus.training.callbacks import UpdateTimer
from parallel_eplus.training.config import TrainConfig
from parallel_eplus.training.train import train


def _scalars(tb_dir: Path, tag: str) -> list[float]:
    ea = EventAccumulator(str(tb_dir), size_guidance={"scalars": 0})
    ea.Reload()
    return [e.value for e in ea.Scalars(tag)] if tag in ea.Tags()["scalars"] else []


def _processes() -> dict[int, tuple[int, str]]:
    """pid -> (parent pid, command line), from /proc."""
    out = {}
    for d in Path("/proc").iterdir():
        if d.name.isdigit():
            try:
                ppid = int((d / "stat").read_text().rsplit(")", 1)[1].split()[1])
                out[int(d.name)] = (ppid, (d / "cmdline").read_bytes().replace(b"\0", b" ").decode(errors="replace"))
            except (OSError, IndexError, ValueError):
                continue
    return out


def hold_priority(marker: str, stop: threading.Event) -> None:
    """Keep every process of the measurement at this script's priority: its own descendants, and those of the
    raylets whose command line holds `marker` (Ray starts its workers at its own niceness, not ours)."""
    mine = os.nice(0)
    while not stop.is_set():
        procs = _processes()
        keep = {os.getpid()} | {p for p, (_, cmd) in procs.items() if "raylet" in cmd.split(" ")[0] and marker in cmd}
        grown = True
        while grown:  # every descendant of those
            more = {p for p, (pp, _) in procs.items() if pp in keep} - keep
            keep |= more
            grown = bool(more)
        for pid in keep:
            try:
                if os.getpriority(os.PRIO_PROCESS, pid) != mine:
                    os.setpriority(os.PRIO_PROCESS, pid, mine)
                # With the kernel's autogroups, nice ranks processes only within their session; sessions
                # share the CPU by their group's own nice, set here (the cluster's nodes run in sessions of
                # their own, and so may a background run).
                Path(f"/proc/{pid}/autogroup").write_text(str(mine))
            except OSError:
                continue
        time.sleep(0.5)


def one_run(backend: str, address: str | None, args: argparse.Namespace, root: Path, k: int) -> dict:
    name = f"{backend}-{k}"
    cfg = TrainConfig(
        workers=args.workers, weathers=args.weathers.split(","), run_days=args.run_days, timesteps=args.timesteps,
        batch_size=args.batch_size, seed=0, run_name=name, runs_dir=str(root / "runs"),
        tensorboard_dir=str(root / "tb"), checkpoint_every=10**9, keep_episodes=0, backend=backend,
        ray_address=address if backend == "ray" else None, workers_per_actor=args.workers_per_actor,
        overlap=args.overlap,
    )  # fmt: skip
    timer = UpdateTimer()
    train(cfg, progress=False, timer=timer)
    row = {"backend": backend, "run": k, "steps": timer.learn_steps, "learn_s": timer.learn_s,
           "steps_per_s": timer.learn_steps / timer.learn_s, "update_s": statistics.median(timer.updates)}  # fmt: skip
    tb = root / "tb" / name
    idle = _scalars(tb, "throughput/learner_idle_share")[1:]  # a learn's first batch is never overlapped
    workers_idle = _scalars(tb, "throughput/workers_idle_share")[1:]
    row.update(idle_share=statistics.mean(idle) if idle else None,
               workers_idle_share=statistics.mean(workers_idle) if workers_idle else None)  # fmt: skip
    if backend == "ray":
        row.update(round_trips_per_batch=_scalars(tb, "ray/round_trips"),
                   wait_s=statistics.mean(_scalars(tb, "ray/wait_s")))  # fmt: skip
    return row


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--address", help="the Ray cluster (default: a local Ray)")
    p.add_argument("--workers", type=int, default=2)
    p.add_argument("--workers-per-actor", type=int, default=1)
    p.add_argument("--weathers", default="CA")
    p.add_argument("--run-days", type=int, default=7)
    p.add_argument("--timesteps", type=int, default=16384)
    p.add_argument("--batch-size", type=int, default=4096)
    p.add_argument("--repeats", type=int, default=2)
    p.add_argument("--overlap", action="store_true", help="both backends with train --overlap")
    p.add_argument("--out", type=Path, help="folder for ray_vs_local.json and .md")
    p.add_argument("--same-priority", metavar="MARKER",
                   help="keep the cluster's processes (raylets whose command line holds MARKER, e.g. /tmp/raycl) "
                        "and ours at this script's niceness and autogroup niceness, so a background run sharing "
                        "the machine weighs on both backends alike (run the script under nice -n -15)")  # fmt: skip
    args = p.parse_args()
    stop = threading.Event()
    if args.same_priority:
        threading.Thread(target=hold_priority, args=(args.same_priority, stop), daemon=True).start()
    logging.basicConfig(level=logging.WARNING, format="%(asctime)s %(levelname)s %(message)s")
    rows = []
    with tempfile.TemporaryDirectory(prefix="ray-vs-local-") as tmp:
        for k in range(args.repeats):
            for backend in ("local", "ray"):
                rows.append(one_run(backend, args.address, args, Path(tmp), k))
                print(json.dumps(rows[-1]), flush=True)
    stop.set()
    local = [r["steps_per_s"] for r in rows if r["backend"] == "local"]
    ray = [r["steps_per_s"] for r in rows if r["backend"] == "ray"]
    ratios = [r / lo for r, lo in zip(ray, local, strict=True)]
    summary = {"config": {k: v for k, v in vars(args).items() if k != "out"}, "runs": rows,
               "local_steps_per_s": statistics.median(local), "ray_steps_per_s": statistics.median(ray),
               "ray_over_local": statistics.median(ratios), "ratios": ratios}  # fmt: skip
    ray_rows = [r for r in rows if r["backend"] == "ray"]
    lines = [
        f"Ray ({args.address or 'local Ray'}) against local: {args.workers} workers, "
        f"{args.workers_per_actor} per actor, {args.run_days}-day episodes, {args.timesteps} steps, "
        f"batch {args.batch_size}, seed 0{', --overlap' if args.overlap else ''}",
        "",
        "| run | local steps/s | Ray steps/s | Ray / local | round trips per batch | learner idle (Ray) | "
        "workers idle: local, Ray |",
        "|---|---|---|---|---|---|---|",
    ]
    local_rows = [r for r in rows if r["backend"] == "local"]

    def share(row: dict, key: str) -> str:
        return f"{row[key]:.2f}" if row.get(key) is not None else "–"

    for k, (lo, r, q) in enumerate(zip(local, ray, ratios, strict=True)):
        rr, lr = ray_rows[k], local_rows[k]
        trips = sorted(set(rr["round_trips_per_batch"]))
        lines.append(f"| {k + 1} | {lo:.0f} | {r:.0f} | {q:.2f} | {', '.join(f'{t:.0f}' for t in trips)} | "
                     f"{share(rr, 'idle_share')} | {share(lr, 'workers_idle_share')}, "
                     f"{share(rr, 'workers_idle_share')} |")  # fmt: skip
    lines.append(f"| median | {summary['local_steps_per_s']:.0f} | {summary['ray_steps_per_s']:.0f} | "
                 f"{summary['ray_over_local']:.2f} | | | |")  # fmt: skip
    text = "\n".join(lines) + "\n"
    print(text)
    if args.out:
        args.out.mkdir(parents=True, exist_ok=True)
        (args.out / "ray_vs_local.json").write_text(json.dumps(summary, indent=2))
        (args.out / "ray_vs_local.md").write_text(text)


if __name__ == "__main__":
    main()
