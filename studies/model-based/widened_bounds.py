"""What a building's own controls save when its comfort is spent (issue 38's office goal): its own thermostat
schedules, each setpoint moved by a constant offset, as energy against discomfort.

    python studies/model-based/widened_bounds.py --building office-small --out results/model-based/office-small/widened

A building whose controls heat to the lower bound of its comfort and cool to the upper one spends the least energy
that keeps every zone inside: what any controller saves beyond them is bought with discomfort, short of timing (the
morning start) and the building's mass. Widening the bounds by a constant prices that discomfort: the energy each
kelvin saves and the discomfort (K·h) it costs, one controller per offset, through `evaluate`'s own sweep and tables.
Offsets are (cooling +K, heating -K) for the first two actions of `--residual-space builtin` (the office's order:
cooling setpoint, then heating); a constant correction moves the setback hours too, which are not scored.
"""

from __future__ import annotations

import argparse
import logging
from pathlib import Path

import numpy as np

from parallel_eplus.buildings.building import load_building
from parallel_eplus.evaluation.controllers import BASELINE_LABEL, Controller
from parallel_eplus.evaluation.results import write_results
from parallel_eplus.evaluation.sweep import run_sweep

log = logging.getLogger("widened")
OFFSETS = ((0.1, 0.1), (0.25, 0.25), (0.5, 0.5), (1.0, 1.0))  # (cooling up, heating down), K


def constant(action: np.ndarray):
    return lambda obs, info: action


def controllers(building: str, offsets) -> list[Controller]:
    """The built-in controls, then each (cooling up, heating down) offset as a constant correction in kelvin."""
    spec = load_building(building)
    halves = np.array([(a.high - a.low) / 2 for a in spec.actions])  # a unit of correction at scale 1 (actions.py)
    if len(halves) < 2:
        raise ValueError(f"{building}: needs a cooling and a heating setpoint action")
    out = [Controller(BASELINE_LABEL, "baseline")]
    for up, down in offsets:
        kelvin = np.zeros(len(halves))
        kelvin[0], kelvin[1] = up, -down
        out.append(Controller(
            f"own +{up:g}/-{down:g} K", "policy", act=constant((kelvin / halves).astype(np.float32)),
            residual_scale=1.0, residual_space="builtin", building=str(spec.spec.path),
            time_features=spec.spec.time_features, run="",
        ))  # fmt: skip
    return out


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--building", default="office-small")
    p.add_argument("--weathers", default="CA,CO,FL", help="training weathers only: this informs a recipe")
    p.add_argument("--run-days", type=int, default=365)
    p.add_argument("--workers", type=int, default=2)
    p.add_argument("--out", type=Path, required=True)
    a = p.parse_args()
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(levelname)s %(name)s: %(message)s")
    df = run_sweep(
        controllers(a.building, OFFSETS), a.weathers.split(","), a.run_days, a.workers, a.out, building=a.building
    )
    for path in write_results(df, a.out):
        log.info("wrote %s", path)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
