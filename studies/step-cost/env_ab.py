"""A CA year (or --days) through `EnergyPlusEnv` from two source trees, and raw EnergyPlus, alternated A B raw,
A B raw...: the medians of per-pair ratios cancel the drift of a shared machine (docs/speed.md).

    .venv/bin/python studies/step-cost/env_ab.py OLD_TREE NEW_TREE --pairs 4

A tree is a checkout's root (`git archive COMMIT | tar -x -C DIR`; add links to idf/ and weather/); each run is a
fresh interpreter with that tree first on PYTHONPATH, started from a neutral directory. `--spins ENV,EP` forces both
sides' spin (seconds) instead of `spin.auto_spins`.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

RUN = r"""
import json, os, sys, tempfile, time
import numpy as np
mode, days, spins = sys.argv[1], int(sys.argv[2]), sys.argv[3]
out = {"mode": mode, "load": os.getloadavg()[0]}
with tempfile.TemporaryDirectory(prefix="parallel-eplus-ab-") as tmp:
    if mode == "raw":
        from parallel_eplus.bench.config import BenchConfig
        from parallel_eplus.bench.raw import _bench_jobs, _raw_runs
        cfg = BenchConfig(raw_days=days)
        jobs = _bench_jobs(cfg, Path(tmp, "raw"), np.full((days * 96, 1, 4), cfg.action), energyplus_csv=False)
        out["s"], [out["stepping_s"]] = _raw_runs(jobs, Path(tmp, "raw"))
    else:
        from parallel_eplus import EnergyPlusEnv
        env = EnergyPlusEnv(weather="CA", run_days=days, output_dir=tmp, energyplus_csv=False)
        proc = env.sim.process
        if spins:
            proc.spin_s, proc.child_spin_s = map(float, spins.split(","))
            proc.auto_spin = False
        action = np.zeros(4, dtype=np.float32)
        try:
            t0 = time.perf_counter()
            env.reset()
            out["first_s"] = time.perf_counter() - t0
            done = False
            while not done:
                done = env.step(action)[2]
            out["s"] = time.perf_counter() - t0
        finally:
            env.close()
        for log in Path(tmp).rglob("energyplus.log"):
            for line in log.read_text().splitlines():
                if line.startswith("bridge "):
                    f = line.split()[1:]
                    out.update({f[i]: float(f[i + 1]) for i in range(0, len(f), 2)})
print(json.dumps(out))
""".replace("import json, os, sys, tempfile, time", "import json, os, sys, tempfile, time\nfrom pathlib import Path")


def _run(tree: Path, mode: str, days: int, spins: str) -> dict:
    env = {**os.environ, "PYTHONPATH": str(tree)}
    with tempfile.TemporaryDirectory() as cwd:  # not a checkout: `-c` puts the working directory first on sys.path
        done = subprocess.run([sys.executable, "-c", RUN, mode, str(days), spins], cwd=cwd, env=env,
                              capture_output=True, text=True)  # fmt: skip
    if done.returncode != 0:
        raise SystemExit(f"{mode} run from {tree} failed:\n{done.stderr}")
    return json.loads(done.stdout.strip().splitlines()[-1])


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("old", type=Path)
    p.add_argument("new", type=Path)
    p.add_argument("--pairs", type=int, default=3)
    p.add_argument("--days", type=int, default=365)
    p.add_argument("--spins", default="", help="ENV,EP spin seconds for both trees (default: automatic)")
    args = p.parse_args()
    med = statistics.median
    pairs = []
    for i in range(args.pairs):
        pair = {k: _run(t, "env", args.days, args.spins) for k, t in (("old", args.old), ("new", args.new))}
        pair["raw"] = _run(args.new, "raw", args.days, "")
        pairs.append(pair)
        waited = pair["new"].get("waited_s", float("nan")) / pair["new"].get("exchanges", 1) * 1e6
        print(f"pair {i + 1}: old {pair['old']['s']:.2f} s, new {pair['new']['s']:.2f} s, raw {pair['raw']['s']:.2f} s;"
              f" new waited {waited:.1f} µs a step; load {pair['raw']['load']:.1f}", flush=True)  # fmt: skip
    for k in ("old", "new"):
        print(f"{k} env/raw median {med(p[k]['s'] / p['raw']['s'] for p in pairs):.3f}")
    print(f"new/old median {med(p['new']['s'] / p['old']['s'] for p in pairs):.3f}")


if __name__ == "__main__":
    main()
