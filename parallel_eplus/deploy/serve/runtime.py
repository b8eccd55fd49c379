"""What an exported folder runs per request, whatever serves it (HTTP or BACnet): a policy network or a planner.

No FastAPI here: the BACnet supervisor loads the same runtime without the web server.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from parallel_eplus.deploy.serve.contract import ONNX_FILE, Contract, InputError, load_session, verified_file


class PolicyRuntime:
    """An exported policy network: readings (and time) in, setpoints out, one onnxruntime call."""

    def __init__(self, directory: Path, contract: Contract):
        self.contract = contract
        self.session, self.io_names = load_session(directory, contract)

    def setpoint_row(self, body: dict) -> np.ndarray:
        """The setpoints in the contract's output order (InputError: a reading it cannot take)."""
        obs = self.contract.observation(body)
        return self.session.run([self.io_names[1]], {self.io_names[0]: obs})[0][0]

    def act(self, body: dict) -> dict:
        row = self.setpoint_row(body)
        if not np.all(np.isfinite(row)):  # pragma: no cover - the graph clips every value it is given
            raise InputError("setpoints", "the controller produced a non-finite setpoint", 500)
        return {"setpoints": self.contract.setpoints(row), "time": body.get("time")}


def load_runtime(directory: Path):
    """The runtime an exported folder holds: a policy network or a planner (`kind`), its files verified."""
    directory = Path(directory)
    contract = Contract.read(directory)
    if contract.data.get("kind") == "planner":
        from parallel_eplus.deploy.serve.planner_runtime import PlannerRuntime

        verified_file(directory, {"file": ONNX_FILE, **contract.data["onnx"]}, "graph")
        verified_file(directory, contract.data["arrays"], "arrays")
        return PlannerRuntime(directory, contract)
    return PolicyRuntime(directory, contract)
