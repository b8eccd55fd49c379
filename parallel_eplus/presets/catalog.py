"""The shipped presets: each a TOML file beside this module, read into a `Preset` and turned into option defaults.

A preset holds a command's settings under the command's name (`[train]`, `[evaluate]`), keyed by the long option
names as typed (`run-days`, `comfort-target`); a NAME=VALUE option (`--mpc`, `--planner`) is a table of its own
(`[train.mpc]`). `defaults(command)` gives argparse's destinations and values, so a flag on the command line
overrides the preset, and the run records what it resolved to.
"""

from __future__ import annotations

import tomllib
from dataclasses import dataclass, field
from importlib import resources
from typing import Any

KINDS = ("datacenter", "thermostat")  # which buildings a preset is made for: a spec's band says which it is
_KEYS = {"name", "version", "kind", "summary", "reason", "evidence", "requires", "train", "evaluate"}


class PresetError(ValueError):
    """A preset that does not exist or does not read."""


@dataclass(frozen=True)
class Preset:
    name: str
    version: int
    kind: str  # one of KINDS
    summary: str  # one line
    reason: str  # why it earned its place, with the figures
    evidence: str  # the results file the reason is read from (a path in the repository)
    requires: str = ""  # "rule": the spec must name a rule as its `controller`
    commands: dict[str, dict[str, Any]] = field(default_factory=dict)  # command -> option -> value

    def defaults(self, command: str) -> dict[str, Any]:
        """The command's option defaults: argparse destinations (`run_days`) to values; a table is NAME=VALUE,..."""
        return {key.replace("-", "_"): _as_option(value) for key, value in self.commands.get(command, {}).items()}

    def describe(self) -> list[str]:
        """Every setting, for `parallel-eplus presets NAME`."""
        lines = [f"{self.name} (version {self.version}, for {self.kind} buildings): {self.summary}", "",
                 *self.reason.splitlines(), f"Evidence: {self.evidence}"]  # fmt: skip
        if self.requires == "rule":
            lines.append("Requires: a spec naming a rule as its `controller` (Guideline 36's supply-air reset).")
        for command, options in self.commands.items():
            lines += ["", f"{command}:"]
            for key, value in options.items():
                lines.append(f"  --{key} {_as_option(value)}" if value is not True else f"  --{key}")
        return lines


def _as_option(value: Any) -> Any:
    if isinstance(value, dict):
        return ",".join(f"{k}={str(v).lower() if isinstance(v, bool) else v}" for k, v in value.items())
    return value


def names() -> list[str]:
    """The shipped presets' names, sorted."""
    return sorted(p.name[:-5] for p in resources.files(__package__).iterdir() if p.name.endswith(".toml"))


def load_preset(name: str) -> Preset:
    """The shipped preset `name`, checked; an unknown name lists the ones there are."""
    if name not in names():
        raise PresetError(f"no preset {name!r}: the presets are {', '.join(names())} (`parallel-eplus presets`)")
    path = resources.files(__package__) / f"{name}.toml"
    try:
        data = tomllib.loads(path.read_text())
    except tomllib.TOMLDecodeError as e:
        raise PresetError(f"preset {name}: {e}") from e
    unknown = set(data) - _KEYS
    missing = {"name", "version", "kind", "summary", "reason", "evidence"} - set(data)
    if unknown or missing or data.get("name") != name or data.get("kind") not in KINDS:
        raise PresetError(f"preset {name}: unknown keys {sorted(unknown)}, missing {sorted(missing)}, "
                          f"name {data.get('name')!r}, kind {data.get('kind')!r} (one of {KINDS})")  # fmt: skip
    commands = {c: data[c] for c in ("train", "evaluate") if c in data}
    return Preset(name=name, version=int(data["version"]), kind=data["kind"], summary=data["summary"],
                  reason=data["reason"], evidence=data["evidence"], requires=data.get("requires", ""),
                  commands=commands)  # fmt: skip


def default_for(kind: str, has_rule: bool = False) -> str:
    """The preset `train --building X` uses when no algorithm or preset is given: the building's kind's."""
    if kind == "datacenter":
        return "paper-trpo"
    return "thermostat-planner-on-reset" if has_rule else "thermostat-planner"
