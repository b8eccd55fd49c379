"""The cluster sizing model of docs/cluster.md: TRPO steps/s against workers and network round trip.

Per batch of B steps on W workers (one actor per node, `cores` workers each), with trajectory fragments:

    T = straggler * (B / W) * t_step        each worker collects its share; the batch waits for the slowest
      + rtt + B * bytes_per_step / bandwidth one order out, one fragment back per actor (in parallel)
      + B * t_merge + U                     the learner merges, then updates (the workers wait meanwhile)

and throughput = B / T. For comparison, the design it replaced made a Ray call per worker step and ran
the policy on the learner: max(straggler * (B / W) * (t_step + rtt + t_call), B * t_learner_step) + U,
where the second term is the learner serving every worker step itself.

    PYTHONPATH=. .venv/bin/python scripts/ray_sizing.py --update-s 1.5 --merge-us 2.0
"""

from __future__ import annotations

import argparse


def fragments_rate(w: int, rtt_s: float, a: argparse.Namespace) -> float:
    b = a.batch
    t = a.straggler * (b / w) * a.step_ms / 1e3 + rtt_s + b * a.bytes_per_step * 8 / a.bandwidth_bps
    return b / (t + b * a.merge_us / 1e6 + a.update_s)


def per_step_rate(w: int, rtt_s: float, a: argparse.Namespace) -> float:
    b = a.batch
    workers = a.straggler * (b / w) * (a.step_ms / 1e3 + rtt_s + a.call_ms / 1e3)
    return b / (max(workers, b * a.learner_step_ms / 1e3) + a.update_s)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--batch", type=int, default=16384)
    p.add_argument("--step-ms", type=float, default=2.5, help="one worker's step: EnergyPlus and the actor's policy")
    p.add_argument("--update-s", type=float, default=1.5, help="the TRPO update of one batch")
    p.add_argument("--merge-us", type=float, default=2.0, help="learner: merging and callbacks, per env step")
    p.add_argument("--straggler", type=float, default=1.15, help="slowest worker's fragment time over the mean")
    p.add_argument("--bytes-per-step", type=float, default=64.0, help="a transition in a fragment")
    p.add_argument("--bandwidth-bps", type=float, default=1e9)
    p.add_argument("--learner-step-ms", type=float, default=0.18, help="old design: learner CPU per worker step")
    p.add_argument("--call-ms", type=float, default=0.5, help="old design: a Ray call's own cost")
    a = p.parse_args()
    rtts = (0.1e-3, 0.5e-3, 2e-3)
    head = " | ".join(f"{r * 1e3:g} ms: fragments / per step" for r in rtts)
    print(f"| workers | {head} |")
    print("|---|" + "---|" * len(rtts))
    for w in (8, 16, 32, 64, 128, 256):
        cells = [f"{fragments_rate(w, r, a):,.0f} / {per_step_rate(w, r, a):,.0f}" for r in rtts]
        print(f"| {w} | " + " | ".join(cells) + " |")
    ceiling = a.batch / (a.batch * a.merge_us / 1e6 + a.update_s)
    crossover = a.straggler * a.batch * a.step_ms / 1e3 / (a.update_s + a.batch * a.merge_us / 1e6)
    print(f"\nceiling B / (merge + U) = {ceiling:,.0f} steps/s; collection = merge + update at W = {crossover:.0f}")


if __name__ == "__main__":
    main()
