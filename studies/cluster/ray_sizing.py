"""The cluster sizing model of docs/cluster.md: TRPO steps/s against workers and network round trip, with the
update after collection (sequential) and overlapped with it (`train --overlap`).

Per batch of B steps on W workers (one actor per node, trajectory fragments):

    C = straggler * (B / W) * t_step + rtt + B * bytes_per_step / bandwidth
                                           collection: the slowest worker's share, one order out and one
                                           fragment back per actor (in parallel)
    L = B * t_merge + U                    the learner's own work: merge and callbacks, then the update

    sequential:  T = C + L                 the workers wait while the learner merges and updates
    overlapped:  T = max(C, L) + B * t_serial
                                           batch k+1 is collected while the learner works on batch k; only
                                           what must precede the next order (the merge into the buffer, the
                                           statistics, the critic's values) keeps the workers waiting

and throughput = B / T; the workers' idle share of each cycle is 1 - (C - rtt - transfer) / T.

    PYTHONPATH=. .venv/bin/python studies/cluster/ray_sizing.py --step-ms 2.2 --update-s 1.3 --merge-us 12
"""

from __future__ import annotations

import argparse


def collection_s(w: int, rtt_s: float, a: argparse.Namespace) -> float:
    return a.straggler * (a.batch / w) * a.step_ms / 1e3 + rtt_s + a.batch * a.bytes_per_step * 8 / a.bandwidth_bps


def learner_s(a: argparse.Namespace) -> float:
    return a.batch * a.merge_us / 1e6 + a.update_s


def rates(w: int, rtt_s: float, a: argparse.Namespace) -> tuple[float, float, float]:
    """(sequential steps/s, overlapped steps/s, the workers' idle share when overlapped)."""
    c, lrn = collection_s(w, rtt_s, a), learner_s(a)
    overlapped = max(c, lrn) + a.batch * a.serial_us / 1e6
    busy = a.straggler * (a.batch / w) * a.step_ms / 1e3
    return a.batch / (c + lrn), a.batch / overlapped, 1 - busy / overlapped


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--batch", type=int, default=16384)
    p.add_argument("--step-ms", type=float, default=2.2, help="one worker's step: EnergyPlus and the actor's policy")
    p.add_argument("--update-s", type=float, default=1.3, help="the TRPO update of one batch")
    p.add_argument("--merge-us", type=float, default=12.0, help="learner: merging and callbacks, per env step")
    p.add_argument("--serial-us", type=float, default=0.1,
                   help="overlapped: what precedes the next order (merge, statistics, values), per step")  # fmt: skip
    p.add_argument("--straggler", type=float, default=1.15, help="slowest worker's fragment time over the mean")
    p.add_argument("--bytes-per-step", type=float, default=64.0, help="a transition in a fragment")
    p.add_argument("--bandwidth-bps", type=float, default=1e9)
    a = p.parse_args()
    rtts = (0.1e-3, 0.5e-3, 2e-3)
    head = " | ".join(f"rtt {r * 1e3:g} ms" for r in rtts)
    print(f"| workers | {head} | workers idle, overlapped |")
    print("|---|" + "---|" * (len(rtts) + 1))
    for w in (8, 16, 32, 64, 128, 256):
        cells = []
        for r in rtts:
            seq, ovl, _ = rates(w, r, a)
            cells.append(f"{seq:,.0f} → **{ovl:,.0f}**")
        idle = rates(w, rtts[1], a)[2]
        print(f"| {w} | " + " | ".join(cells) + f" | {idle:.0%} |")
    lrn = learner_s(a)
    ceiling = a.batch / (lrn + a.batch * a.serial_us / 1e6)
    crossover = a.straggler * a.batch * a.step_ms / 1e3 / lrn
    print(
        f"\nlearner per batch L = {lrn:.2f} s; overlapped ceiling B / (L + serial) = {ceiling:,.0f} steps/s,"
        f" reached at W = {crossover:.0f} (collection = L); sequential approaches B / L = {a.batch / lrn:,.0f}"
    )


if __name__ == "__main__":
    main()
