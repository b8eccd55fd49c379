#!/usr/bin/env python3
"""Derive idf/ from the authors' EnergyPlus 22.2 baseline model.

The committed models in idf/ are this script's output; it exists so every change to the authors'
file is written down once and can be re-applied (tests check idf/ is up to date with it).

    python tools/make_models.py [--source PATH] [--check]

Changes, in order:
1. Transition 22.2 -> 25.2: version line; People 'ZoneAveraged' -> 'EnclosureAveraged';
   Coil:Cooling:DX:SingleSpeed gains 'Crankcase Heater Capacity Function of Temperature Curve
   Name' after 'Crankcase Heater Capacity' (without it later fields shift by one).
   The 2023 rated evaporator fan power takes NREL's current value (934.4; only ratings use it).
2. Outputs: the authors' long hourly/monthly report list is replaced by the timestep variables the
   episode records read, written as CSV only (OutputControl:Files), so a year stays a few MB.
   The PUE EMS program and its verbose EMS dictionary (a large .edd) go with them.
3. Agent variant: the two SetpointManager:SingleZone:Cooling objects are commented out, so the
   agent's actuators own the controlled nodes' setpoints.

It also derives the CRAC data center's agent variant from its committed model in idf/ (see its spec):
4. 1ZoneDataCenterCRAC_wApproachTemp_agent.idf: SetpointManager:Warmest "Supply air control" commented out: with
   it active the supply-node actuator has no effect (idf/NOTES.md); its two design days commented
   out too (without them the CO weather year starts; see crac_agent).
Running the weather year rather than the design days, and the run period, are not model edits: the engine
prepares every run's copy of any model (parallel_eplus/buildings/idf/prepare.py).
"""

from __future__ import annotations

import argparse
import re
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
DEFAULT_SOURCE = ROOT.parent / "shared" / "reference" / "2ZoneDataCenterHVAC_wEconomizer-baseline-22.2.idf"
BASELINE = ROOT / "idf" / "2ZoneDataCenterHVAC_wEconomizer.idf"
AGENT = ROOT / "idf" / "2ZoneDataCenterHVAC_wEconomizer_agent.idf"
CRAC = ROOT / "idf" / "1ZoneDataCenterCRAC_wApproachTemp.idf"
CRAC_AGENT = ROOT / "idf" / "1ZoneDataCenterCRAC_wApproachTemp_agent.idf"

HEADER = """\
! Derived by tools/make_models.py from the 2ZoneDataCenterHVAC_wEconomizer baseline model as
! published by the authors of Moriyama et al. (2018) for EnergyPlus 22.2, itself EnergyPlus's
! example file (licence: EnergyPlus-LICENSE.txt beside this file). Do not edit by hand: change
! the script and re-run it.
"""

OUTPUTS = """\
  !****************************************************************
  ! Outputs read by parallel-eplus episode records (timestep frequency, CSV only).

  OutputControl:Files,
    Yes,                     !- Output CSV
    No,                      !- Output MTR
    No,                      !- Output ESO
    Yes,                     !- Output EIO
    No,                      !- Output Tabular
    No,                      !- Output SQLite
    No,                      !- Output JSON
    No,                      !- Output AUDIT
    No,                      !- Output Space Sizing
    No,                      !- Output Zone Sizing
    No,                      !- Output System Sizing
    No,                      !- Output DXF
    No,                      !- Output BND
    No,                      !- Output RDD
    No,                      !- Output MDD
    No,                      !- Output MTD
    Yes,                     !- Output END
    No,                      !- Output SHD
    No,                      !- Output DFS
    No,                      !- Output GLHE
    No,                      !- Output DelightIn
    No,                      !- Output DelightELdmp
    No,                      !- Output DelightDFdmp
    No,                      !- Output EDD
    No,                      !- Output DBG
    No,                      !- Output PerfLog
    No,                      !- Output SLN
    No,                      !- Output SCI
    No,                      !- Output WRL
    No,                      !- Output Screen
    No,                      !- Output ExtShd
    No,                      !- Output Tarcog
    No;                      !- Output Plant Component Sizing

  Output:Variable,Environment,Site Outdoor Air Drybulb Temperature,timestep;
  Output:Variable,West Zone,Zone Mean Air Temperature,timestep;
  Output:Variable,East Zone,Zone Mean Air Temperature,timestep;
  Output:Variable,Whole Building,Facility Total Electricity Demand Rate,timestep;
  Output:Variable,Whole Building,Facility Total Building Electricity Demand Rate,timestep;
  Output:Variable,Whole Building,Facility Total HVAC Electricity Demand Rate,timestep;
  Output:Variable,West Zone Supply Fan,Fan Air Mass Flow Rate,timestep;
  Output:Variable,East Zone Supply Fan,Fan Air Mass Flow Rate,timestep;
  Output:Variable,West Zone DEC Outlet Node,System Node Setpoint Temperature,timestep;
  Output:Variable,West Zone IEC Outlet Node,System Node Setpoint Temperature,timestep;
  Output:Variable,West Zone CCoil Air Outlet Node,System Node Setpoint Temperature,timestep;
  Output:Variable,West Air Loop Outlet Node,System Node Setpoint Temperature,timestep;
  Output:Variable,West Air Loop Outlet Node,System Node Temperature,timestep;
  Output:Variable,East Zone DEC Outlet Node,System Node Setpoint Temperature,timestep;
  Output:Variable,East Zone IEC Outlet Node,System Node Setpoint Temperature,timestep;
  Output:Variable,East Zone CCoil Air Outlet Node,System Node Setpoint Temperature,timestep;
  Output:Variable,East Air Loop Outlet Node,System Node Setpoint Temperature,timestep;
  Output:Variable,East Air Loop Outlet Node,System Node Temperature,timestep;
"""

# Where the authors' output section starts (the PUE EMS block precedes Output:* objects).
OUTPUT_SECTION_START = (
    "  !****************************************************************\n  ! Power Utilization Effectiveness"
)


def _sub_once(pattern: str, repl: str, text: str, count: int) -> str:
    new, n = re.subn(pattern, repl, text, flags=re.MULTILINE)
    if n != count:
        raise SystemExit(f"make_models: expected {count} match(es) of {pattern!r}, found {n}")
    return new


def transition(src: str) -> str:
    """Bring the authors' 22.2 model to 25.2 and trim its outputs: the baseline variant."""
    text = src.replace("\r\n", "\n")
    text = _sub_once(r"^  Version,22\.2;", "  Version,25.2;", text, 1)
    text = _sub_once(
        r"^(\s+)zoneaveraged,(\s+)!- Mean Radiant Temperature Calculation Type",
        r"\1EnclosureAveraged,\2!- Mean Radiant Temperature Calculation Type",
        text,
        2,
    )
    text = _sub_once(
        r"^(    ,                        !- Crankcase Heater Capacity \{W\}\n)",
        r"\1    ,                        !- Crankcase Heater Capacity Function of Temperature Curve Name\n",
        text,
        2,
    )
    text = _sub_once(
        r"^    ,                        (!- 2023 Rated Evaporator Fan Power Per Volume Flow Rate)",
        r"    934.4,                   \1",
        text,
        2,
    )
    start = text.find(OUTPUT_SECTION_START)
    if start < 0:
        raise SystemExit("make_models: the authors' output section was not found")
    return HEADER + text[:start] + OUTPUTS


def agent_variant(baseline: str) -> str:
    """Comment out the setpoint managers that own the nodes our actuators drive."""
    pattern = r"^  SetpointManager:SingleZone:Cooling,\n(?:.*\n)*?.*;.*\n"

    def comment(m: re.Match[str]) -> str:
        lines = m.group(0).splitlines(keepends=True)
        note = "  ! Disabled in the agent variant: parallel-eplus actuators own these setpoints.\n"
        return note + "".join("!" + line[1:] for line in lines)

    text, n = re.subn(pattern, comment, baseline, flags=re.MULTILINE)
    if n != 2:
        raise SystemExit(f"make_models: expected 2 SetpointManager:SingleZone:Cooling, found {n}")
    return text


def _derived(source: Path, change: str) -> str:
    return (
        f"! Derived by tools/make_models.py from {source.name} (beside this file): {change}\n"
        "! Do not edit by hand: change the script and re-run it.\n"
    )


def crac_agent(text: str) -> str:
    """Comment out the Warmest manager so the supply-node actuator owns the CRAC's supply temperature."""
    pattern = r"^  SetpointManager:Warmest,\n    Supply air control,(?:.*\n)*?.*;.*\n"

    def comment(m: re.Match[str]) -> str:
        note = "  ! Disabled in the agent variant: parallel-eplus actuators own this setpoint.\n"
        return note + "".join("!" + line[1:] for line in m.group(0).splitlines(keepends=True))

    text, n = re.subn(pattern, comment, text, flags=re.MULTILINE)
    if n != 1:
        raise SystemExit(f"make_models: expected 1 SetpointManager:Warmest 'Supply air control', found {n}")
    # Without the Warmest manager, EnergyPlus still simulated the Denver cooling design day ahead of the
    # Golden (CO) weather year, and its IT-equipment inlet read an unset supply node (-289 C): a fatal
    # RhoAir <= 0. Nothing here sizes from them, so the agent copy has no design days (CA's days unchanged).
    design_day = r"^  SizingPeriod:DesignDay,\n(?:.*\n)*?.*;.*\n"

    def drop(m: re.Match[str]) -> str:
        note = "  ! Disabled in the agent variant: no sizing runs from it (make_models.crac_agent).\n"
        return note + "".join("!" + line[1:] for line in m.group(0).splitlines(keepends=True))

    text, n = re.subn(design_day, drop, text, flags=re.MULTILINE)
    if n != 2:
        raise SystemExit(f"make_models: expected 2 SizingPeriod:DesignDay objects in the CRAC model, found {n}")
    return _derived(CRAC, "SetpointManager:Warmest 'Supply air control' and the design days disabled.") + text


def build(source: Path) -> dict[Path, str]:
    baseline = transition(source.read_text(encoding="latin-1"))
    return {
        BASELINE: baseline,
        AGENT: agent_variant(baseline),
        CRAC_AGENT: crac_agent(CRAC.read_text(encoding="latin-1")),
    }


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--source", type=Path, default=DEFAULT_SOURCE)
    parser.add_argument("--check", action="store_true", help="fail if idf/ differs from the script's output")
    args = parser.parse_args(argv)
    outputs = build(args.source)
    stale = [p for p, text in outputs.items() if not p.exists() or p.read_text(encoding="latin-1") != text]
    if args.check:
        for p in stale:
            print(f"out of date: {p.relative_to(ROOT)}", file=sys.stderr)
        return 1 if stale else 0
    for path, text in outputs.items():
        path.write_text(text, encoding="latin-1")
        print(f"wrote {path.relative_to(ROOT)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
