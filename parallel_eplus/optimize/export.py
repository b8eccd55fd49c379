"""The chosen controller written where a building's systems can use it: a learned one by `parallel-eplus export` (ONNX,
or the planner, with its contract controller.json, ready for `serve`) with the preset's evaluation settings; a rule as a
note of what to program (export takes trained controllers only); the own controls as nothing at all, and a note saying
why, so an empty folder is never mistaken for a failed export."""

from __future__ import annotations

import shutil

from parallel_eplus.optimize.candidates import LEARNED, OWN, RESET
from parallel_eplus.optimize.command import failure, run_command
from parallel_eplus.optimize.folders import BuildingFolder
from parallel_eplus.optimize.prepare import RULE
from parallel_eplus.presets.catalog import Preset

NOTE = "CHOSEN.md"


def export(folder: BuildingFolder, chosen: str, reason: str, controller: str | None, preset: Preset | None,
           workers: int, show: bool) -> dict:  # fmt: skip
    """Write DIR/controller/ for `chosen`; returns the stage's fields."""
    out = folder.controller
    shutil.rmtree(out, ignore_errors=True)
    if chosen == OWN:
        return {"state": "done", "written": None, "note": "no controller: keep your own controls"}
    if chosen == RESET:
        out.mkdir(parents=True)
        (out / NOTE).write_text(
            "# Chosen: Guideline 36's supply-air reset\n\n"
            f"{reason}\n\nA rule, not a trained controller: `parallel-eplus export` writes trained ones only. Program "
            "ASHRAE Guideline 36's trim-and-respond reset of the supply-air temperature on outdoor air and the zones' "
            f"cooling requests in your building's controls, as `{RULE}` runs it (its settings: "
            "parallel_eplus/buildings/rules/air_reset.py, `ResetConfig`); every thermostat stays on its own schedule. "
            f"Its spec: {folder.rule_spec.name}.\n"
        )  # fmt: skip
        return {"state": "done", "written": str(out / NOTE), "note": "a rule: what to program, in CHOSEN.md"}
    assert chosen == LEARNED and controller and preset
    args = ["export", controller, "-o", str(out), "--workers", str(workers), "--quiet"]
    planner = preset.commands.get("evaluate", {}).get("planner")
    if planner and controller.rstrip("/").endswith("planner"):
        args += ["--planner-options", ",".join(f"{k}={v}" for k, v in planner.items())]
    outcome = run_command(args, folder.logs / "export.log", folder.root, f"{folder.name}: export", show=show)
    if outcome.returncode or not (out / "controller.json").is_file():
        return {"state": "failed", "error": f"export: {failure(outcome.log)}"}
    (out / NOTE).write_text(f"# Chosen: {preset.name}\n\n{reason}\n\nServe it: `parallel-eplus serve {out}` "
                            "(docs/deploy.md).\n")  # fmt: skip
    return {
        "state": "done",
        "written": str(out / "controller.json"),
        "note": f"`export` of {preset.name}",
        "seconds": round(outcome.seconds, 1),
    }
