#!/usr/bin/env python3
"""Re-centre a residual policy's setpoint corrections on zero (an experiment of results/paper).

Under `--residual` the rule-based controller keeps the supply air at its 10 C floor, where a negative
setpoint correction is clipped away. A policy's mean correction can drift deep into that dead zone,
where no sample tells it anything. This shifts the biases of the setpoint outputs so the mean
correction is zero at the observations' running mean, and writes a policy for `train --init-from`.

    python studies/residual-recentre/recentre_residual.py MODEL_DIR OUT_DIR
"""

from __future__ import annotations

import argparse
import logging
import shutil
from pathlib import Path

import torch as th
from sb3_contrib import TRPO

from parallel_eplus.runs.policy_files import normalization_file

log = logging.getLogger("recentre")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("model_dir", type=Path, help="holds model.zip and its statistics (vecnormalize.npz or .pkl)")
    parser.add_argument("out_dir", type=Path)
    args = parser.parse_args()
    logging.basicConfig(level=logging.INFO, format="%(message)s")

    model = TRPO.load(args.model_dir / "model.zip", device="cpu")
    with th.no_grad():
        at_mean = th.zeros(1, model.observation_space.shape[0])  # a normalized observation at its mean
        mean = model.policy.action_net(model.policy.mlp_extractor.forward_actor(at_mean))[0]
        log.info("mean correction at the running mean (West, East setpoint; West, East fan): %s", mean.numpy().round(2))
        model.policy.action_net.bias[:2] -= mean[:2]
    args.out_dir.mkdir(parents=True, exist_ok=True)
    model.save(args.out_dir / "model.zip")
    stats = normalization_file(args.model_dir / "model.zip")
    shutil.copy(stats, args.out_dir / stats.name)
    log.info("written: %s", args.out_dir / "model.zip")


if __name__ == "__main__":
    main()
