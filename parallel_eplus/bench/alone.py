"""EnergyPlus alone: the yardstick with none of our code in the loop (issue 39).

The same prepared model as an episode's (`idf_prep.prepare_idf`), plus an EMS program of EnergyPlus's own that
holds each action element's actuators at a constant value (the model's initial action during warmup, as the env's
EnergyPlus side holds it), run by `pyenergyplus` with no callback of ours: runs one after another in one process, a
new API state per run. What the env costs beyond it is what our side adds: the process per episode, its imports,
the callbacks and the pipes.

`run_alone(out_dir, [(idf, epw), ...])` runs them in a fresh process (`RUNNER`) and times it.
"""

from __future__ import annotations

import subprocess
import sys
import time
from pathlib import Path

from parallel_eplus.buildings.building import Building
from parallel_eplus.buildings.idf.prepare import prepare_idf
from parallel_eplus.buildings.idf.takeover import taken_setpoints


def _name(i: int, j: int) -> str:
    return f"pe_a{i}_{j}"  # EMS names: letters, digits and underscores


CALLING_POINT = "BeginTimestepBeforePredictor"


def ems_objects(building: Building, action: list[float], calling_point: str = CALLING_POINT) -> str:
    """EMS objects holding every actuator of action element i at `action[i]` (physical units), the initial
    action during warmup. Set once per zone timestep, before the predictor: an actuator keeps its value, and
    nothing of the model's writes these between there and where the env's EnergyPlus side writes them."""
    objects, hold, warm = [], [], []
    for i, element in enumerate(building.actions):
        for j, a in enumerate(element.actuators):
            fields = [_name(i, j), a.key, a.component_type, a.control_type]
            objects.append("EnergyManagementSystem:Actuator,\n  " + ",\n  ".join(fields) + ";")
            hold.append(f"  SET {_name(i, j)} = {action[i]!r}")
            warm.append(f"  SET {_name(i, j)} = {element.initial!r}")
    lines = ["IF WarmupFlag == 1", *warm, "ELSE", *hold, "ENDIF"]
    objects.append("EnergyManagementSystem:Program,\n  pe_hold,\n" + ",\n".join(lines) + ";")
    objects.append(f"EnergyManagementSystem:ProgramCallingManager,\n  pe_hold_manager,\n  {calling_point},\n  pe_hold;")
    return "\n\n".join(objects) + "\n"


def alone_model(
    building: Building, target: Path, run_days: int, action: list[float], calling_point: str = CALLING_POINT
) -> Path:
    """The episode's model (EnergyPlus's CSV off, as training runs it) with the EMS program appended."""
    target.parent.mkdir(parents=True, exist_ok=True)
    control = building.control()
    prepare_idf(
        control.idf,
        target,
        run_days,
        energyplus_csv=False,
        takeover=taken_setpoints(control.actions),
        ventilation=building.spec.demand_ventilation,
    )
    with target.open("a", encoding="latin-1") as f:
        f.write("\n\n" + ems_objects(building, action, calling_point))
    return target


def run_alone(out_dir: Path, runs: list[tuple[Path, Path]]) -> dict[str, float | list[float]]:
    """The runs one after another in one fresh process: its wall seconds (start-up and imports included), and
    each run's own seconds."""
    out_dir.mkdir(parents=True, exist_ok=True)
    args = [str(p) for pair in runs for p in pair]
    t0 = time.perf_counter()
    done = subprocess.run([sys.executable, "-c", RUNNER, str(out_dir), *args], capture_output=True, text=True)
    wall = time.perf_counter() - t0
    if done.returncode != 0:
        raise RuntimeError(f"EnergyPlus alone failed: {done.stderr[-2000:]}")
    each = [float(ln.split()[1]) for ln in done.stdout.splitlines() if ln.startswith("run_s ")]
    return {"wall_s": wall, "runs_s": each}


# The process that runs EnergyPlus alone imports nothing of ours (our package would import gymnasium, this one
# the whole bench): only pyenergyplus, as a user's script running EnergyPlus would.
RUNNER = """
import sys, time
from pathlib import Path
from pyenergyplus.api import EnergyPlusAPI
out, pairs = Path(sys.argv[1]), sys.argv[2:]
api = EnergyPlusAPI()
for k in range(0, len(pairs), 2):
    t0 = time.perf_counter()
    state = api.state_manager.new_state()
    api.runtime.set_console_output_status(state, False)
    run_dir = out / f"run{k // 2}"
    status = api.runtime.run_energyplus(state, ["-d", str(run_dir), "-w", pairs[k + 1], pairs[k]])
    api.state_manager.delete_state(state)
    if status != 0:
        sys.exit(f"EnergyPlus exited with status {status} ({run_dir})")
    print(f"run_s {time.perf_counter() - t0:.6f}", flush=True)
"""


def alone_seconds(cfg, workdir: Path, days: int | None = None, runs: int = 1) -> float:
    """EnergyPlus alone under the bench's constant action (`cfg`: a BenchConfig) for `days` (default its
    `raw_days`), `runs` periods one after another in one process: wall seconds, start-up included, as the env run
    and `raw_seconds` are timed."""
    from parallel_eplus.bench.config import bench_building
    from parallel_eplus.bench.raw import _physical
    from parallel_eplus.buildings.weather.files import resolve_weather

    building = bench_building(cfg)
    action = _physical([cfg.action] * len(building.actions), cfg.building)
    idf = alone_model(building, workdir / "model.idf", days or cfg.raw_days, action)
    epw = building.spec.weathers.get(cfg.weather) or resolve_weather(cfg.weather)
    return float(run_alone(workdir / "out", [(idf, epw)] * runs)["wall_s"])
