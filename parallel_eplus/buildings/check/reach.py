"""`building check`'s proof that each node-setpoint action reaches its node (issue 52).

Resolving an actuator's handle says nothing about whether EnergyPlus acts on it: with the CRAC's own setpoint manager
left in, the supply node's setpoint read back as the agent's while the coil supplied the manager's. So for every
action on a `System Node Setpoint / Temperature Setpoint` the check runs the prepared copy (the one training runs,
its managers taken over: buildings/idf/takeover.py) for three days from January 1 and three from July 1, each in a
child process (killable, as the check's own probe): the other actions held at their initial values, the node
actions at their low end in even hours of the day and their high end in odd ones (as the engine, every action at
its initial value through sizing and warm-up). Each node's setpoint and temperature are compared with the action
while air or water flows through it, the first step of each hour left out, both runs' samples pooled. Alternating
hours rather than runs holding one end each: the paper's data center held at 40 C supply air for days heats its
zones past what EnergyPlus accepts, and stops.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
from dataclasses import dataclass
from pathlib import Path

from parallel_eplus.buildings.building import applies_before_predictor
from parallel_eplus.buildings.idf.takeover import NODE_SETPOINT, taken_setpoints
from parallel_eplus.buildings.spec.load import BuildingSpec

REACH_DAYS = 3  # a run's days: prototypes make January 1 a holiday (systems off), so two working days follow
# (first day of the year, days): a winter run and a summer one, samples pooled; in January alone the large office's
# chillers sat idle (its coils' load on the economizer), the chilled water at 6.7 C whatever its setpoint
REACH_PERIODS = ((1, REACH_DAYS), (182, REACH_DAYS))
TOLERANCE_K = 0.5  # a node within this of its setpoint follows it
SHARE = 0.5  # of the samples with flow that must be within the tolerance: the equipment may not hold an end of the
# range at every hour (the data center, cooling only, sits below 40 C supply while its mixed air is colder: 94-95 %
# within), but a node the action does not set stays off it nearly always (0-1 % within on the medium office)
SETPOINT_SHARE = 0.9  # of them whose setpoint must read back as the action's
FLOW_SHARE = 0.01  # a sample counts when the node's flow is above this share of its largest in the run
TIMEOUT_S = 600.0  # a large model sizes for minutes on a busy machine
NODE_VARIABLES = ("System Node Setpoint Temperature", "System Node Temperature", "System Node Mass Flow Rate")


@dataclass(frozen=True)
class Reach:
    """One node-setpoint action held at one end of its range: what its first node did while flowing."""

    action: str
    node: str
    end: str  # "low" or "high"
    target: float
    samples: int  # control steps with flow through the node
    within: float  # share of them with the node's temperature within TOLERANCE_K of the target
    setpoint_ok: float  # share of them with the node's setpoint read back as the target
    mean_c: float  # the node's mean temperature over them

    @property
    def ok(self) -> bool:
        return self.within >= SHARE and self.setpoint_ok >= SETPOINT_SHARE

    def text(self) -> str:
        share = f"{100 * self.within:.0f} % of {self.samples} flowing steps within {TOLERANCE_K} K"
        return f"{self.action} reaches {self.node} at its {self.end} end ({self.target:g} C: {share})"


def node_actions(spec: BuildingSpec) -> list[tuple[int, str]]:
    """(action index, node) to judge for each action whose actuators set nodes' temperature setpoints: every node of
    the action that is a loop's supply node (idf/loops.py), else its last (the 2-zone data center's actions set
    each coil's outlet on the way to the loop's: only the loop's must reach the setpoint)."""
    from parallel_eplus.buildings.idf.loops import topology

    supplies = topology(spec.idf.read_text(encoding="latin-1")).supplies
    out = []
    for i, a in enumerate(spec.actions):
        if not a.actuators or any(x.component.lower() != NODE_SETPOINT for x in a.actuators):
            continue
        nodes = [x.key for x in a.actuators if (x.key.upper(), "temperature") in taken_setpoints([a])]
        loops = [n for n in nodes if n.upper() in supplies]
        out += [(i, n) for n in dict.fromkeys(loops or nodes[-1:])]
    return out


def _request(spec: BuildingSpec) -> dict:
    judged = node_actions(spec)
    nodes = {i for i, _ in judged}
    low = [a.low if i in nodes else a.initial for i, a in enumerate(spec.actions)]
    high = [a.high if i in nodes else a.initial for i, a in enumerate(spec.actions)]
    actuators = [[[x.component, x.control, x.key] for x in a.actuators] for a in spec.actions]
    return {"idf": str(spec.idf), "held": [low, high], "initial": [a.initial for a in spec.actions],
            "actuators": actuators, "nodes": sorted({n for _, n in judged}),
            "takeover": [list(t) for t in taken_setpoints(spec.actions)], "start_day": 1, "days": REACH_DAYS,
            "before_predictor": applies_before_predictor(spec)}  # fmt: skip


def prove_reach(spec: BuildingSpec, weather: Path) -> tuple[list[str], list[str], list[Reach]]:
    """(problems, notes, what each node did at each end) for the spec's node-setpoint actions; no actions: nothing."""
    actions = node_actions(spec)
    if not actions:
        return [], [], []
    samples: dict[str, list] = {}
    for start, days in REACH_PERIODS:  # one after the other: the check shares the machine
        with tempfile.TemporaryDirectory(prefix="eplus-reach-") as tmp:
            request = Path(tmp, "request.json")
            request.write_text(json.dumps(_request(spec) | {"start_day": start, "days": days}))
            cmd = [sys.executable, "-m", "parallel_eplus.buildings.check.reach", "--probe", str(request), "--weather",
                   str(weather)]  # fmt: skip
            try:
                proc = subprocess.run(cmd, cwd=tmp, capture_output=True, text=True, timeout=TIMEOUT_S)
                err = proc.stderr
            except subprocess.TimeoutExpired:  # run() kills the child before raising
                err = f"no answer within {TIMEOUT_S:.0f} s"
            report = Path(tmp, "samples.json")
            if not report.is_file():
                why = f"(the run from day {start}) {(err or '').strip()[-800:]}"
                return [f"actions: cannot prove the node setpoints reach their nodes: {why}"], [], []
            for node, rows in json.loads(report.read_text()).items():
                samples.setdefault(node, []).extend(rows)
    return judge(spec, actions, samples)


def judge(spec: BuildingSpec, actions, samples: dict) -> tuple[list[str], list[str], list[Reach]]:
    """Each node action's verdict from both runs' samples (per node: setpoint, temperature, flow per step)."""
    problems, notes, reaches = [], [], []
    for i, node in actions:
        a = spec.actions[i]
        rows = samples[node.upper()]
        least = max(FLOW_SHARE * max((r[2] for r in rows), default=0.0), 1e-6)
        for k, (end, target) in enumerate((("low", a.low), ("high", a.high))):
            flowing = [(s, t) for s, t, f, odd, first in rows if odd == k and not first and f > least]
            where = f'actions[{i}] "{a.name}" at its {end} end ({target:g})'
            if not flowing:
                notes.append(f"{where}: no flow through {node} in the check's days: not proven")
                continue
            within = sum(abs(t - target) <= TOLERANCE_K for _, t in flowing) / len(flowing)
            set_ok = sum(abs(s - target) <= 1e-3 for s, _ in flowing) / len(flowing)
            mean = sum(t for _, t in flowing) / len(flowing)
            reaches.append(Reach(a.name, node, end, target, len(flowing), within, set_ok, mean))
            if set_ok < SETPOINT_SHARE:
                other = sum(s for s, _ in flowing) / len(flowing)
                problems.append(f"{where}: {node}'s setpoint read {other:.2f} C on average, not the action's: another "
                                "setpoint manager or an EMS program of the model overwrites it")  # fmt: skip
            elif within < SHARE:
                problems.append(
                    f"{where}: {node} stayed at {mean:.2f} C on average ({100 * within:.0f} % of {len(flowing)} "
                    f"flowing steps within {TOLERANCE_K} K): its setpoint reads back as the action's, but no component "
                    "controls to it there, another setpoint manager's value wins upstream, or the equipment cannot "
                    "reach it; narrow the range or choose the node the loop controls"
                )
    return problems, notes, reaches


# --- the child process: the prepared copy, every action held, the nodes read at each zone timestep's end ---


def _probe(request_file: Path, weather: Path) -> None:
    from pyenergyplus.api import EnergyPlusAPI

    from parallel_eplus.buildings.idf.prepare import prepare_idf

    request = json.loads(request_file.read_text())
    folder = request_file.parent
    model = folder / "model.idf"
    prepare_idf(Path(request["idf"]), model, request["days"], energyplus_csv=False, start_day=request["start_day"],
                takeover=tuple(tuple(t) for t in request["takeover"]))  # fmt: skip
    api = EnergyPlusAPI()
    state = api.state_manager.new_state()
    api.runtime.set_console_output_status(state, False)
    for node in request["nodes"]:
        for variable in NODE_VARIABLES:
            api.exchange.request_variable(state, variable, node)
    handles: dict = {}
    samples: dict[str, list] = {node.upper(): [] for node in request["nodes"]}

    def hold(s) -> None:
        if not handles:
            if not api.exchange.api_data_fully_ready(s):
                return
            low, high = request["held"]
            handles["act"] = [(api.exchange.get_actuator_handle(s, *names), (first, lo, hi))
                              for names_list, first, lo, hi in zip(request["actuators"], request["initial"], low, high,
                                                                   strict=True)
                              for names in names_list]  # fmt: skip
            handles["nodes"] = {n.upper(): [api.exchange.get_variable_handle(s, v, n) for v in NODE_VARIABLES]
                                for n in request["nodes"]}  # fmt: skip
        warming = api.exchange.warmup_flag(s) or api.exchange.kind_of_sim(s) != 3  # as the engine: the initial action
        k = 0 if warming else 1 + api.exchange.hour(s) % 2  # initial, low in even hours, high in odd ones
        for handle, values in handles["act"]:
            api.exchange.set_actuator_value(s, handle, values[k])

    def read(s) -> None:
        if not handles or api.exchange.warmup_flag(s) or api.exchange.kind_of_sim(s) != 3:
            return
        odd, first = api.exchange.hour(s) % 2, api.exchange.zone_time_step_number(s) == 1
        for node, hs in handles["nodes"].items():
            samples[node].append([*(api.exchange.get_variable_value(s, h) for h in hs), odd, first])

    if request["before_predictor"]:  # where the engine applies actions (bridge.py)
        api.runtime.callback_begin_system_timestep_before_predictor(state, hold)
    else:
        api.runtime.callback_after_predictor_after_hvac_managers(state, hold)
    api.runtime.callback_end_zone_timestep_after_zone_reporting(state, read)
    code = api.runtime.run_energyplus(state, ["-d", str(folder / "out"), "-w", str(weather), str(model)])
    if code == 0 and all(samples.values()):
        (folder / "samples.json").write_text(json.dumps(samples))
    else:
        err = folder / "out" / "eplusout.err"
        sys.stderr.write(err.read_text(errors="replace")[-1500:] if err.is_file() else f"exit {code}\n")


def main(argv: list[str] | None = None) -> int:
    """The child process: `--probe REQUEST.json --weather EPW` writes samples.json beside the request."""
    p = argparse.ArgumentParser(prog="python -m parallel_eplus.buildings.check.reach")
    p.add_argument("--probe", type=Path, required=True)
    p.add_argument("--weather", type=Path, required=True)
    args = p.parse_args(argv)
    _probe(args.probe, args.weather)
    return 0


if __name__ == "__main__":
    sys.exit(main())
