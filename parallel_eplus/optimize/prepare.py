"""The building made ready as its starter's notes ask a user: `building init` on a model, the recommended actions and
the example tariff uncommented (what the prototypes study did by hand), `building check`; a spec the user wrote is
used as it is, copied with its files named by absolute path so the copies beside it (the reset's) resolve them too."""

from __future__ import annotations

import logging
import re
from pathlib import Path

from parallel_eplus.optimize.command import failure, run_command
from parallel_eplus.optimize.folders import BuildingFolder

log = logging.getLogger(__name__)

RULE = "parallel_eplus.buildings.rules.air_reset:SupplyAirReset"  # Guideline 36's supply-air reset
TARIFF_LINE = '# tariff = { Electricity = { file = "commercial-tou-demand.toml" } }'  # the starter's example tariff
_HEADINGS = ("# all ", "# the one thermostat's", "# the one air loop's")
_KINDS = ("thermostats'", "thermostat's", "air loops' supply", "air loop's supply")
_PATHS = re.compile(r'"([^"\n]+\.(?:idf|epw|toml|csv|json))"', flags=re.IGNORECASE)


def recommended(starter: str) -> str:
    """The starter with its recommended actions (every thermostat's setpoints together, per schedule; every air loop's
    supply air together) and the example commercial tariff with demand charges uncommented."""
    out, on = [], False
    for line in starter.splitlines():
        if line.startswith(_HEADINGS) and any(k in line for k in _KINDS):
            on = True  # a block's heading: its lines follow, to a blank line
        elif on and line.startswith("# "):
            line = line[2:]
        elif not line.strip():
            on = False
        if line.startswith(TARIFF_LINE):
            line = line[2:]
        out.append(line)
    return "\n".join(out) + "\n"


def with_absolute_paths(text: str, folder: Path) -> str:
    """A spec's text with every file it names relative to `folder` (its own) named by absolute path; bare names of
    built-in files, found nowhere in `folder`, stay as they are."""

    def absolute(m: re.Match) -> str:
        path = Path(m.group(1))
        return f'"{(folder / path).resolve()}"' if not path.is_absolute() and (folder / path).is_file() else m.group(0)

    return _PATHS.sub(absolute, text)


def with_models(text: str, spec: Path) -> str:
    """A spec's `idf` and `baseline_idf` named by the paths its loader resolves them to (a built-in spec names the
    package's own copies of its models by bare name, which only the built-in specs find)."""
    from parallel_eplus.buildings.spec.load import load_spec

    loaded = load_spec(spec)
    for key, path in (("idf", loaded.idf), ("baseline_idf", loaded.baseline_idf)):
        if path is not None:
            text = re.sub(
                rf'^({key}\s*=\s*)"[^"\n]*"', lambda m, p=path: f'{m.group(1)}"{p}"', text, count=1, flags=re.M
            )
    return text


def with_rule(text: str, rule: str = RULE) -> str:
    """The spec naming `rule` as its `controller` (replacing another's)."""
    if re.search(r"^controller\s*=", text, flags=re.M):
        return re.sub(r"^controller\s*=.*$", f'controller = "{rule}"', text, count=1, flags=re.M)
    return re.sub(r"^(idf\s*=.*)$", rf'\1\ncontroller = "{rule}"', text, count=1, flags=re.M)


def source_of(argument: str) -> Path:
    """A model or spec file, or a built-in spec's name (`office-small`)."""
    path = Path(argument)
    if path.is_file():
        return path.resolve()
    if path.suffix.lower() not in (".idf", ".toml"):
        from parallel_eplus.buildings.resources import spec_file

        try:
            return Path(spec_file(argument))
        except (FileNotFoundError, ValueError):
            pass
    raise FileNotFoundError(f"{argument}: no such model (.idf), spec (.toml) or built-in spec")


def prepare(folder: BuildingFolder, weather: str, show: bool) -> dict:
    """The spec, checked against its model; returns the stage's fields (state done, or failed with why)."""
    folder.root.mkdir(parents=True, exist_ok=True)
    source = folder.source
    if source.suffix.lower() == ".idf":
        starter = folder.root / "starter.toml"
        if not starter.is_file():
            out = run_command(["building", "init", str(source), "--weather", weather, "-o", str(starter),
                               "--name", folder.name], folder.logs / "prepare.log", folder.root,
                              f"{folder.name}: building init", show=show)  # fmt: skip
            if out.returncode or not starter.is_file():
                return {"state": "failed", "error": f"building init: {failure(out.log)}"}
        text = recommended(starter.read_text())
        how = "starter from `building init`, its recommended actions and the example tariff uncommented"
    else:
        text = with_models(with_absolute_paths(source.read_text(), source.parent), source)
        how = f"your spec, as given ({source})"
    folder.spec.write_text(text)
    out = run_command(["building", "check", str(folder.spec)], folder.logs / "prepare.log", folder.root,
                      f"{folder.name}: building check", show=show)  # fmt: skip
    if out.returncode:
        return {"state": "failed", "error": f"building check: {failure(out.log)}"}
    from parallel_eplus.buildings.spec.load import load_spec

    spec = load_spec(folder.spec)
    air = [a.name for a in spec.actions if any(x.component.lower() == "system node setpoint" for x in a.actuators)]
    folder.rule_spec.write_text(with_rule(text))
    log.info("%s: checked (%d actions: %s)", folder.name, len(spec.actions), ", ".join(a.name for a in spec.actions))
    return {
        "state": "done",
        "how": how,
        "actions": [a.name for a in spec.actions],
        "supply_air": air,
        "kind": "thermostat" if spec.reward.thermostat else "datacenter",
        "controller": spec.controller,
    }
