"""An exported planner as the BACnet supervisor's controller: each step, the request an HTTP client would send.

The served planner keeps no state (planner_runtime.py); over HTTP its client carries the last setpoints, the last
plan, the guard's and the rule's state and the month's demand peaks from request to request. Here the supervisor is
that client: it keeps them between steps, reads the rule's extra points beside the sensors, and keeps the demand
peaks from the meter point as a building's meter would. The forecast cannot come over BACnet: the planner must be
exported with `--persistence` (the outdoor reading held over the horizon; the answers say so).
"""

from __future__ import annotations

import datetime as dt
import logging
from pathlib import Path

import numpy as np

from parallel_eplus.deploy.serve.contract import Contract, InputError
from parallel_eplus.deploy.serve.runtime import load_runtime

log = logging.getLogger("parallel_eplus.deploy.bacnet.supervisor")


class PlannerSteps:
    """(readings, time) -> the planner's setpoints, or None where the building's own controls should act."""

    def __init__(self, directory: Path, contract: Contract):
        if contract.data["forecast"].get("missing") != "persistence":
            raise ValueError(
                f"{directory} is a planner that needs a weather forecast with every request, which BACnet does not "
                "carry: export it with --persistence (`parallel-eplus export RUN -o DIR --persistence`) to supervise "
                "over BACnet, or serve it over HTTP with the forecast in each request (docs/deploy.md)"
            )
        self.runtime = load_runtime(directory)  # its files checked against the contract
        self.outputs = [o["name"] for o in contract.outputs]
        self.last = {o["name"]: float(o["initial"]) for o in contract.outputs}
        self.plan = self.guard = self.rule_state = None
        rule = contract.data.get("rule") or {}
        self.rule_readings = [r["name"] for r in rule.get("readings", [])]
        self.demand = None
        if contract.data.get("demand_peaks_kw"):  # the month's running peaks, from the meter's readings
            from parallel_eplus.buildings.pricing.bill import DemandTracker

            tariff = self.runtime.energy.tariffs["Electricity"]
            self.demand = DemandTracker(tariff, contract.data["control_step_s"] / 60)
            self.charges = contract.data["demand_peaks_kw"]["charges"]
            self.meter = contract.data["planner"]["demand"]["power"]

    @property
    def points(self) -> list[str]:
        """What it reads beyond the contract's sensors (the rule's readings)."""
        return self.rule_readings

    def answer(self, sensors: dict[str, float], extra: dict[str, float], time: str, step) -> np.ndarray | None:
        body = {"time": time, "sensors": sensors, "last_setpoints": self.last, "plan": self.plan}
        if self.guard is not None:
            body["guard"] = self.guard
        if self.rule_readings:
            body |= {"rule_readings": extra, "rule_state": self.rule_state}
        if self.demand is not None:
            when = dt.datetime.fromisoformat(time)
            self.demand.observe(when, sensors[self.meter])
            body["demand_peaks_kw"] = self.demand.month_peaks(self.charges, when)
        try:
            answer = self.runtime.act(body)
        except InputError as e:
            log.warning("fallback at step %s: %s; the building's own controls act", step, e)
            return self._given_back(time)
        self.guard, self.rule_state = answer.get("guard"), answer.get("rule_state")
        if answer["fallback"]:
            log.warning("fallback at step %s: %s; the building's own controls act", step, answer["reason"])
            return self._given_back(time)
        setpoints = [answer["setpoints"][n]["value"] for n in self.outputs]
        self.last, self.plan = dict(zip(self.outputs, setpoints, strict=True)), answer.get("plan")
        return np.array(setpoints)

    def _given_back(self, time: str) -> None:
        """The step goes to the building's own controls (the supervisor relinquishes): what is in force then is
        theirs, which the next request's last setpoints take as what they set at this date and time (recorded at
        export); the search starts afresh."""
        when = dt.datetime.fromisoformat(time)
        own = np.clip(self.runtime.own(when), self.runtime.low, self.runtime.high)
        self.last, self.plan = dict(zip(self.outputs, map(float, own), strict=True)), None
        return None
