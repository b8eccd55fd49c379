"""An exported controller replayed on an episode `evaluate` recorded: does it give every setpoint the policy gave?

A step table's row k holds observation k and the setpoints that led to it, which the policy chose from observation
k-1; so the graph's answer to row k-1 must equal row k's setpoints (observation 0, before the first step, is not
recorded). No torch: it reads the step table and runs onnxruntime.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from parallel_eplus.buildings.datacenter import SCHEDULE_FEATURES, TIME_FEATURES, schedule_features, time_features
from parallel_eplus.deploy.serve.contract import ONNX_FILE, Contract


def observations(contract: Contract, steps: pd.DataFrame) -> np.ndarray:
    """The observation each recorded step's readings and time make, as the env built it (float32)."""
    sensors = steps[[s["name"] for s in contract.sensors]].to_numpy(np.float64)
    features = contract.features
    extra = []
    schedule = tuple(tuple(p) for p in contract.data.get("schedule", ()))
    for t in pd.to_datetime(steps["time"]).dt.to_pydatetime():
        row = time_features(t) if any(f in TIME_FEATURES for f in features) else ()
        if any(f in SCHEDULE_FEATURES for f in features):
            row += schedule_features(t, schedule)
        extra.append(row)
    return np.hstack([sensors, np.array(extra, np.float64).reshape(len(steps), -1)]).astype(np.float32)


def replay(controller_dir: Path, steps: pd.DataFrame) -> dict:
    """Max |graph - recorded| per setpoint (physical units) over an episode's steps, and how many were compared."""
    import onnxruntime as ort

    contract = Contract.read(controller_dir)
    session = ort.InferenceSession(str(Path(controller_dir) / ONNX_FILE), providers=["CPUExecutionProvider"])
    onnx_io = contract.data["onnx"]
    out = session.run([onnx_io["output"]], {onnx_io["input"]: observations(contract, steps)})[0]
    names = [o["name"] for o in contract.outputs]
    diff = np.abs(out[:-1] - steps[names].to_numpy(np.float64)[1:])
    return {"steps": len(diff), "max_abs_diff": dict(zip(names, diff.max(axis=0).tolist(), strict=True))}
