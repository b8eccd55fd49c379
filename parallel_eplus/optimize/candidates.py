"""The controllers a building is offered, each as `evaluate` selects it: its own controls, the rules it supports
(Guideline 36's supply-air reset) and its preset's learned controller, picked from what the spec says the building is
(`band = "thermostat"`: a thermostat building; otherwise a data center)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from parallel_eplus.optimize.folders import BuildingFolder
from parallel_eplus.presets.catalog import Preset, default_for, load_preset

OWN, RESET, LEARNED = "own", "reset", "learned"
# `paper-trpo` needs millions of steps (the paper's 10.5M) and holds 82 % in band: a data center within a budget gets
# the planner trained through its model, which exports as a network (results/model-based/datacenter-2zone/)
DATACENTER_PRESET = "datacenter-planner"


@dataclass(frozen=True)
class Candidate:
    key: str  # its folder under eval/ and its name in the csvs
    label: str  # in the report
    spec: Path
    args: tuple[str, ...]  # `evaluate` options selecting it
    controller: str  # its rows' `controller` in evaluate's results.csv


def own(folder: BuildingFolder) -> Candidate:
    return Candidate(OWN, "own controls", folder.spec, ("--baseline",), "Baseline")


def reset(folder: BuildingFolder) -> Candidate:
    return Candidate(RESET, "Guideline 36 reset", folder.rule_spec, ("--rbc",), "Rule-based")


def reset_refusal(folder: BuildingFolder) -> str | None:
    """Why the reset cannot run on this building (its own words), or None when it can."""
    from parallel_eplus.buildings.rules.air_reset import SupplyAirReset

    try:
        SupplyAirReset(str(folder.rule_spec))
    except (ValueError, KeyError) as e:
        return str(e)
    return None


def preset_for(kind: str, reset_applies: bool, asked: str | None = None) -> Preset:
    """The preset `--preset` names, else the building's: the thermostat planner (on the reset where it applies), or
    the data center's planner."""
    if asked:
        return load_preset(asked)
    if kind == "datacenter":
        return load_preset(DATACENTER_PRESET)
    return load_preset(default_for("thermostat", reset_applies))


def learned_spec(folder: BuildingFolder, preset: Preset) -> Path:
    """A preset riding a rule trains and is scored on the spec naming it."""
    return folder.rule_spec if preset.requires == "rule" else folder.spec


def controller_path(run: Path, preset: Preset) -> Path:
    """What a finished run is scored and exported as: a model-based run's planner where it distils no network (the
    thermostat presets), else its network (model.zip)."""
    train = preset.commands.get("train", {})
    no_network = train.get("mpc", {}).get("distill") is False or not (run / "model.zip").is_file()
    if train.get("algorithm") == "mpc" and no_network:
        return run / "planner"
    return run / "model.zip"


def scores_planner(preset: Preset) -> bool:
    """Whether the preset's controller is scored as a planner (a model-based run that distils no network)."""
    train = preset.commands.get("train", {})
    return train.get("algorithm") == "mpc" and train.get("mpc", {}).get("distill") is False


def evaluate_options(preset: Preset) -> tuple[str, ...]:
    """The preset's `[evaluate]` settings as options (`--planner band_thermostats=baseline`)."""
    return tuple(option_args(preset.commands.get("evaluate", {})))


def option_args(options: dict) -> list[str]:
    """A preset's command table as command-line options: booleans as bare flags, tables as NAME=VALUE,..."""
    args: list[str] = []
    for key, value in options.items():
        if value is True:
            args.append(f"--{key}")
        elif value is False or value is None:
            continue
        elif isinstance(value, dict):
            text = ",".join(f"{k}={str(v).lower() if isinstance(v, bool) else v}" for k, v in value.items())
            args += [f"--{key}", text]
        else:
            args += [f"--{key}", str(value)]
    return args


def learned(folder: BuildingFolder, preset: Preset, run: Path) -> Candidate:
    path = controller_path(run, preset)
    label = f"learned ({preset.name})"
    return Candidate(LEARNED, label, learned_spec(folder, preset), ("--policy", f"{path}=Learned",
                     *evaluate_options(preset)), "Learned")  # fmt: skip
