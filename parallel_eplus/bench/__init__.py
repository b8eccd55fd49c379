"""`parallel-eplus bench`: our overhead against EnergyPlus alone, measured in one run on this machine.

1. two yardsticks, wall seconds from process start to exit: EnergyPlus alone (alone.py: the prepared model, the
   constant action held by EnergyPlus's own EMS program, no code of ours), and "pipes only" (raw.py: our
   EnergyPlus-side program applying the constant action with no pipe exchange);
2. env: the same period and action stepped through `EnergyPlusEnv` (reset + steps, wall seconds);
3. vector env: aggregate steps/s with 1 and N workers, and the scaling efficiency, with the workers
   pipelined (each stepped as soon as it answers, as training steps them) and in lockstep, beside
   the machine's own: N raw runs at once against one, and N workers each stepped alone in a process
   of its own (no shared learner: the ceiling any vector env can reach here), and raw EnergyPlus
   replaying the same actions with no pipes (1 and N processes): what the physics alone costs;
4. training: env steps/s inside TRPO `learn` with N workers, against the vector env's rate and raw's,
   and the floor for a million steps here (raw EnergyPlus's time under those actions plus the updates);
5. the same training through a local Ray (one actor per worker, each collecting its fragment of the
   batch), against the local backend: the Ray backend's price, re-measured whenever speed work lands;
6. time to first observation, peak RSS of one EnergyPlus worker and of the learner;
7. with `short`: short episodes (short.py): ten consecutive 1- and 7-day episodes in one env against EnergyPlus alone
   running the same ten periods, reset latency, TRPO steps/s at 1, 7, 14 and 365-day episodes;
8. with `boptest`: what `parallel-eplus boptest`'s POST /advance adds per control step over EnergyPlus stepped alone
   in process, over the same period (boptest.py: the server in a process of its own, HTTP on loopback).

Random actions in 3 are drawn like an untrained TRPO policy's (N(0, 1) clipped to [-1, 1]), so 3 and
4 ask EnergyPlus for the same kind of work: control changes EnergyPlus's own cost several-fold.

A top layer beside experiments: it may import training and everything below it; not cli.
"""

from __future__ import annotations

import json
import logging
import os
import resource
import statistics
import tempfile
from dataclasses import asdict, replace
from pathlib import Path

from parallel_eplus.bench.alone import alone_seconds
from parallel_eplus.bench.boptest import advance_overhead, overhead_rows
from parallel_eplus.bench.config import BenchConfig, _exploring_actions
from parallel_eplus.bench.rates import env_run, independent_rate, training_rate, vector_rate
from parallel_eplus.bench.raw import _physical, raw_rate, raw_seconds, replay_run

log = logging.getLogger(__name__)

__all__ = ["BenchConfig", "_physical", "format_table", "raw_rate", "replay_run", "run"]


def run(cfg: BenchConfig, out: Path | None = None) -> dict:
    """Every measurement, back to back, on this machine; written to `out` as JSON when given."""
    if cfg.building:  # a typo fails here, in seconds, not in the first EnergyPlus worker
        from parallel_eplus.buildings.check.names import check_building

        cfg = replace(cfg, building=str(check_building(cfg.building).path))
    results: dict = {"config": asdict(cfg), "machine": {"cores": os.cpu_count()}}
    with tempfile.TemporaryDirectory(prefix="parallel-eplus-bench-") as tmp:
        tmp = Path(tmp)
        # Back to back within each repeat, and ratios taken per repeat: this machine's speed drifts by
        # 10-20 % from one minute to the next, which medians of separate series would not cancel.
        raw, raw_n, envs, alone = [], [], [], []
        for i in range(cfg.repeats):
            alone.append(alone_seconds(cfg, tmp / f"alone{i}"))
            raw.append(raw_seconds(cfg, tmp / f"raw{i}"))
            envs.append(env_run(cfg, tmp / f"env{i}"))
            # The machine's own ceiling on scaling: N raw runs at once against one alone.
            raw_n.append(raw_seconds(cfg, tmp / f"rawN{i}", copies=cfg.workers))
        worker_rss_mb = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024
        results["raw_s"] = statistics.median(raw)
        results["raw_n_s"] = statistics.median(raw_n)
        results["raw_scaling"] = statistics.median(r / n for r, n in zip(raw, raw_n, strict=True))
        results["env_s"] = statistics.median(e["seconds"] for e in envs)
        results["env_steps_per_s"] = statistics.median(e["steps_per_s"] for e in envs)
        results["env_over_raw"] = statistics.median(e["seconds"] / r for e, r in zip(envs, raw, strict=True))
        results["alone_s"] = statistics.median(alone)
        results["env_over_alone"] = statistics.median(e["seconds"] / a for e, a in zip(envs, alone, strict=True))
        results["first_obs_s"] = statistics.median(e["first_obs_s"] for e in envs)
        one, many, lockstep, alone, phys_1, phys_n = [], [], [], [], [], []
        for i in range(cfg.repeats):
            # What the physics costs under the same exploring actions, beside what we make of it.
            phys_1.append(raw_rate(cfg, tmp / f"p1_{i}", _exploring_actions(cfg, 1)))
            phys_n.append(raw_rate(cfg, tmp / f"pN_{i}", _exploring_actions(cfg, cfg.workers)))
            one.append(vector_rate(cfg, 1, tmp / f"v1_{i}"))
            many.append(vector_rate(cfg, cfg.workers, tmp / f"vN_{i}"))
            lockstep.append(vector_rate(cfg, cfg.workers, tmp / f"vL_{i}", pipelined=False))
            alone.append(independent_rate(cfg, tmp / f"alone_{i}"))
        results["raw_exploring_1_steps_per_s"] = statistics.median(phys_1)
        results["raw_exploring_n_steps_per_s"] = statistics.median(phys_n)
        results["vector_1_over_raw"] = statistics.median(r["steps_per_s"] / p for r, p in zip(one, phys_1, strict=True))
        results["vector_n_over_raw"] = statistics.median(
            r["steps_per_s"] / p for r, p in zip(many, phys_n, strict=True)
        )
        results["vector_1_steps_per_s"] = statistics.median(r["steps_per_s"] for r in one)
        results["vector_n_steps_per_s"] = statistics.median(r["steps_per_s"] for r in many)
        results["vector_1_cores_busy"] = statistics.median(r["cores_busy"] for r in one)
        results["vector_n_cores_busy"] = statistics.median(r["cores_busy"] for r in many)
        results["scaling_efficiency"] = results["vector_n_steps_per_s"] / (
            cfg.workers * results["vector_1_steps_per_s"]
        )
        results["lockstep_n_steps_per_s"] = statistics.median(r["steps_per_s"] for r in lockstep)
        results["lockstep_scaling"] = results["lockstep_n_steps_per_s"] / (
            cfg.workers * results["vector_1_steps_per_s"]
        )
        results["independent_n_steps_per_s"] = statistics.median(alone)
        results["independent_scaling"] = results["independent_n_steps_per_s"] / (
            cfg.workers * results["vector_1_steps_per_s"]
        )
        tr = training_rate(cfg, tmp / "train")
        results["train_steps_per_s"] = tr["steps_per_s"]
        results["train_over_vector"] = tr["steps_per_s"] / results["vector_n_steps_per_s"]
        results["update_s"] = tr["update_s"]
        results["million_steps_minutes"] = 1e6 / tr["steps_per_s"] / 60
        results["train_over_raw"] = tr["steps_per_s"] / results["raw_exploring_n_steps_per_s"]
        # The floor for 1M steps here: EnergyPlus's own time under these actions, plus the updates.
        results["million_steps_floor_minutes"] = (
            1e6 / results["raw_exploring_n_steps_per_s"] + 1e6 / cfg.batch_size * tr["update_s"]
        ) / 60
        if cfg.ray:
            ray_tr = training_rate(cfg, tmp / "train-ray", backend="ray")
            results["train_ray_steps_per_s"] = ray_tr["steps_per_s"]
            results["train_ray_over_local"] = ray_tr["steps_per_s"] / tr["steps_per_s"]
        if cfg.short:
            results["short"] = short_episodes(cfg, tmp / "short")
        if cfg.boptest:
            results["boptest"] = advance_overhead(cfg, tmp / "boptest")
        results["worker_peak_rss_mb"] = worker_rss_mb
        results["learner_peak_rss_mb"] = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    if out is not None:
        out.parent.mkdir(parents=True, exist_ok=True)
        out.write_text(json.dumps(results, indent=2))
    return results


def short_episodes(cfg: BenchConfig, workdir: Path) -> dict:
    """Issue 39's figures: consecutive short episodes against EnergyPlus alone, resets, TRPO by episode length."""
    from parallel_eplus.bench.short import consecutive, parked_resets, training

    out = {f"{d}d": consecutive(d, 10, cfg.repeats, cfg.weather, ("prepared", "cold")) for d in (1, 7)}
    out |= parked_resets(1, 30, cfg.weather, workdir / "parked")
    out |= training([1, 7, 14, 365], cfg.train_steps, 1)
    return out


def _short_rows(s: dict) -> list[tuple[str, str, str]]:
    rows = []
    for d in ("1d", "7d"):
        c = s[d]
        took = f"{c['prepared_s']:.2f} s (cold {c['cold_s']:.2f})"
        ratio = f"/alone {c['prepared_over_alone']:.2f}, cold {c['cold_over_alone']:.2f} (target <= 1.10)"
        rows.append((f"10 consecutive {d[:-1]}-day episodes, one env", took, f"{ratio}; alone {c['alone_s']:.2f} s"))
    c = s["1d"]
    rows.append(("reset, back to back (1-day)", f"p50 {c['reset_p50_ms']:.0f} / p99 {c['reset_p99_ms']:.0f} ms",
                 f"cold p50 {c['cold_reset_p50_ms']:.0f} / p99 {c['cold_reset_p99_ms']:.0f} ms"))  # fmt: skip
    rows.append(("reset, the prepared episode parked", f"p50 {s['parked_reset_p50_ms']:.1f} / p99 "
                 f"{s['parked_reset_p99_ms']:.1f} ms", "target p99 <= 50 ms"))  # fmt: skip
    for d, goal in ((1, " (target >= 0.75)"), (7, " (target >= 0.90)"), (14, "")):
        rows.append((f"TRPO learn, 2 workers, {d}-day episodes", f"{s[f'train_{d}d_steps_per_s']:.0f} steps/s",
                     f"{s[f'train_{d}d_over_365d']:.2f} of year-long{goal}"))  # fmt: skip
    rows.append(("TRPO learn, 2 workers, year-long episodes", f"{s['train_365d_steps_per_s']:.0f} steps/s", ""))
    return rows


def format_table(r: dict) -> str:
    """The benchmark as the table `parallel-eplus bench` prints, targets beside the figures."""
    c = r["config"]
    n = c["workers"]
    building = Path(c["building"]).stem if c.get("building") else "datacenter-2zone"
    rows = [
        ("building", building, f"weather {c['weather']}"),
        *([("EnergyPlus alone, EMS holds the action", f"{r['alone_s']:.2f} s for {c['raw_days']} days",
             "the yardstick: no code of ours")] if "alone_s" in r else []),
        ("our EnergyPlus side, no pipes", f"{r['raw_s']:.2f} s for {c['raw_days']} days", "the pipes-only yardstick"),
        ("EnergyPlusEnv, same action", f"{r['env_s']:.2f} s ({r['env_steps_per_s']:.0f} steps/s)",
         (f"env/alone {r['env_over_alone']:.2f} (target <= 1.10); " if "env_over_alone" in r else "")
         + f"pipes only: env/raw {r['env_over_raw']:.2f}"),
        (f"raw EnergyPlus, {n} runs at once", f"{r['raw_n_s']:.2f} s",
         f"the machine's own scaling {r['raw_scaling']:.2f}"),
        ("raw EnergyPlus, exploring actions, 1 run", f"{r['raw_exploring_1_steps_per_s']:.0f} steps/s",
         "the physics alone, start-up excluded"),
        (f"raw EnergyPlus, exploring actions, {n} at once", f"{r['raw_exploring_n_steps_per_s']:.0f} steps/s", ""),
        ("vector env, 1 worker", f"{r['vector_1_steps_per_s']:.0f} steps/s",
         f"{r['vector_1_over_raw']:.2f} of raw; {r['vector_1_cores_busy']:.2f} cores busy"),
        (f"vector env, {n} workers, pipelined", f"{r['vector_n_steps_per_s']:.0f} steps/s",
         f"scaling {r['scaling_efficiency']:.2f} (target >= 0.90); {r['vector_n_over_raw']:.2f} of raw"),
        (f"vector env, {n} workers, lockstep", f"{r['lockstep_n_steps_per_s']:.0f} steps/s",
         f"scaling {r['lockstep_scaling']:.2f}"),
        (f"{n} workers stepped alone, at once", f"{r['independent_n_steps_per_s']:.0f} steps/s",
         f"scaling {r['independent_scaling']:.2f}: the ceiling without lockstep or learner"),
        (f"TRPO learn, {n} workers", f"{r['train_steps_per_s']:.0f} steps/s",
         f"train/vector {r['train_over_vector']:.2f} (target >= 0.75); {r['train_over_raw']:.2f} of raw"),
        *([(f"TRPO learn, {n} workers, Ray backend", f"{r['train_ray_steps_per_s']:.0f} steps/s",
            f"ray/local {r['train_ray_over_local']:.2f} (target >= 0.90); local Ray, one actor per worker")]
          if "train_ray_steps_per_s" in r else []),
        ("TRPO update of one 16k batch", f"{r['update_s']:.2f} s", ""),
        ("1M TRPO steps", f"{r['million_steps_minutes']:.1f} min",
         f"target <= 15 min; EnergyPlus's own time and the updates: {r['million_steps_floor_minutes']:.1f} min"),
        ("time to first observation", f"{r['first_obs_s']:.2f} s", "target <= 2 s"),
        *(_short_rows(r["short"]) if "short" in r else []),
        *(overhead_rows(r["boptest"]) if "boptest" in r else []),
        ("peak RSS: EnergyPlus worker / learner", f"{r['worker_peak_rss_mb']:.0f} / {r['learner_peak_rss_mb']:.0f} MB",
         "worker target <= 300 MB"),
    ]  # fmt: skip
    width = max(len(a) for a, _, _ in rows)
    return "\n".join(f"{a:<{width}}  {b:<28} {t}" for a, b, t in rows)
