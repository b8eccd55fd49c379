"""`train --config run.toml`: a run's settings from one TOML file, the way RL Zoo and Sinergym keep experiments.

The file's keys are the command's long options without their dashes, written with `-` or `_` (`run-days = 7`,
`run_days = 7`); values are typed as TOML types them and checked as the option checks its text (`workers = 2.5`
is refused, as `--workers 2.5` is). An on/off flag takes a boolean (`time-features = true`); a comma-separated
option also takes an array (`weathers = ["CA", "CO", "FL"]`); `--mpc`, `--sac` and `--mbpo` take a table
(`[mpc]` then `horizon = 12`) or their `NAME=VALUE,...` text. Paths are read as on the command line (from the
working directory).

The file's values become the parser's defaults (`set_defaults`) before the final parse, so the command line
overrides the file; a `--mpc` on the command line is added to the file's `[mpc]` settings, its own winning where
both name one. An unknown key is an error naming it (and the nearest option). The run's config.json then holds the
resolved settings, as for any run.
"""

from __future__ import annotations

import argparse
import sys
import tomllib
from pathlib import Path
from typing import Any

CONFIG_DEST = "config"
TYPE_NAMES = {int: "a whole number", float: "a number"}


class ConfigFile(argparse.Action):
    """`--config FILE`: stored like any option; `SettingsParser` reads the file before its final parse."""

    def __call__(self, parser, namespace, values, option_string=None):
        setattr(namespace, self.dest, Path(values))


class SettingsParser(argparse.ArgumentParser):
    """An ArgumentParser that, where it has a `ConfigFile` or `PresetOption` option, parses twice: once to find the
    preset and the file, then with their values as defaults (the file's over the preset's), so the command line
    overrides both. Otherwise a plain ArgumentParser."""

    def parse_known_args(self, args=None, namespace=None):
        if not any(isinstance(a, (ConfigFile, PresetOption)) for a in self._actions):
            return super().parse_known_args(args, namespace)
        args = list(sys.argv[1:] if args is None else args)
        saved = dict(self._defaults), {id(a): a.default for a in self._actions}
        try:
            return self._parse_with_settings(args, namespace)
        finally:  # a parser parses again as it was built (tests, `optimize` and sweeps reuse one)
            self._defaults.clear()
            self._defaults.update(saved[0])
            for action in self._actions:
                action.default = saved[1][id(action)]

    def _parse_with_settings(self, args: list[str], namespace):
        first, _ = super().parse_known_args(args, None)
        path = getattr(first, CONFIG_DEST, None)
        values = read_config(self, path) if path is not None else {}
        if getattr(first, "preset", None) is None and values.get("preset"):
            first.preset = values["preset"]  # `preset = "..."` in the file: the command line's --preset wins
        preset = preset_defaults(self, first, args)  # the lowest: a preset, then the file, then the command line
        for dest, value in preset.items():  # a file's [mpc] adds to the preset's, its own winning
            values[dest] = f"{value},{values[dest]}" if _is_settings(self, dest) and values.get(dest) else \
                values.get(dest, value)  # fmt: skip
        self.set_defaults(**values)
        namespace, extras = super().parse_known_args(args, namespace)
        for dest, value in values.items():  # `--mpc` on the command line adds to the file's [mpc]
            given = getattr(namespace, dest)
            if isinstance(value, str) and _is_settings(self, dest) and given is not value and given:
                setattr(namespace, dest, f"{value},{given}")
        namespace.from_config = values  # what the file set (commands.py: a setting given, not a default)
        return namespace, extras


class PresetOption(argparse.Action):
    """`--preset NAME`: a shipped preset's settings for this command (parallel_eplus/presets/) as the defaults under a
    `--config` file's and the command line's; the name is kept (`args.preset`) so the run records it."""

    def __call__(self, parser, namespace, values, option_string=None):
        setattr(namespace, self.dest, values)


def preset_defaults(parser: argparse.ArgumentParser, first: argparse.Namespace, args: list[str]) -> dict[str, Any]:
    """The defaults of the preset named with `--preset`, else, for `train --building SPEC` with no `--algorithm`,
    `--config` or `--resume`, the building's own preset (a spec's `band = "thermostat"`: the thermostat planner).
    Each value is checked as its option checks its text; `parser.error` for an unknown preset."""
    from parallel_eplus.presets.catalog import PresetError, load_preset

    name = getattr(first, "preset", None)
    if name is None and _building_default_applies(parser, first, args):
        name = building_preset(first.building)
        if name is not None:
            first.preset = name
            import logging

            logging.getLogger(__name__).info(
                "%s: training its kind's preset %s (`parallel-eplus presets %s`; --algorithm or --preset to choose)",
                first.building, name, name)  # fmt: skip
    if name is None:
        return {}
    try:
        preset = load_preset(name)
    except PresetError as e:
        parser.error(str(e))
    command = parser.prog.split()[-1]
    values = option_defaults(parser, preset.commands.get(command, {}), f"--preset {name}")
    values["preset"] = name
    return values


def _building_default_applies(parser: argparse.ArgumentParser, first: argparse.Namespace, args: list[str]) -> bool:
    if parser.prog.split()[-1] != "train" or not getattr(first, "building", None):
        return False
    chosen = ("--algorithm", "--resume", "--config", "--init-from")
    return not any(a == c or a.startswith(c + "=") for a in args for c in chosen)


def building_preset(building: str) -> str | None:
    """The preset a spec's kind trains by default: its `band = "thermostat"` and a rule it names say which."""
    from parallel_eplus.buildings.resources import spec_file
    from parallel_eplus.buildings.spec import load_spec
    from parallel_eplus.presets.catalog import default_for

    try:
        spec = load_spec(spec_file(building))
    except (OSError, ValueError):
        return None  # the command reports the spec's problems itself
    if spec.preset is not None:
        return spec.preset
    if not spec.reward.thermostat:
        return None  # a data center: the paper's TRPO, today's defaults
    return default_for("thermostat", has_rule="air_reset" in (spec.controller or ""))


def _is_settings(parser: argparse.ArgumentParser, dest: str) -> bool:
    return any(a.dest == dest and getattr(a, "settings", None) for a in parser._actions)


def options_by_key(parser: argparse.ArgumentParser) -> dict[str, argparse.Action]:
    """Each long option a file may set, by its name without dashes (`run_days`)."""
    out = {}
    for action in parser._actions:
        if isinstance(action, (argparse._HelpAction, ConfigFile)):
            continue
        for option in action.option_strings:
            if option.startswith("--"):
                out[option[2:].replace("-", "_")] = action
    return out


def read_config(parser: argparse.ArgumentParser, path: Path) -> dict[str, Any]:
    """The file's settings as the parser's defaults, by dest; `parser.error` (exit 2) on anything it cannot mean."""
    where = f"--config {path}"
    try:
        data = tomllib.loads(Path(path).read_text())
    except OSError as e:
        parser.error(f"{where}: {e.strerror or e}")
    except tomllib.TOMLDecodeError as e:
        parser.error(f"{where}: not valid TOML: {e}")
    return option_defaults(parser, data, where)


def option_defaults(parser: argparse.ArgumentParser, data: dict[str, Any], where: str) -> dict[str, Any]:
    """Settings keyed by long option (`run-days` or `run_days`) as the parser's defaults by dest, each checked as
    its option checks its text; `parser.error` naming `where` and the key for anything it cannot mean. (A `--config`
    file's; any other source of option defaults, a preset's, can be checked the same way.)"""
    options = options_by_key(parser)
    values: dict[str, Any] = {}
    for key, value in data.items():
        name = key.replace("-", "_")
        if name == CONFIG_DEST:
            parser.error(f"{where}: a config file cannot name another (`config`)")
        action = options.get(name)
        if action is None:
            from parallel_eplus.buildings.spec.sections import did_you_mean

            parser.error(f"{where}: unknown setting {key!r}{did_you_mean(name.replace('_', '-'), _dashed(options))}; "
                         f"its keys are {parser.prog}'s long options (--help lists them), with - or _")  # fmt: skip
        if action.dest in values:
            parser.error(f"{where}: {key!r} given twice (as - and as _)")
        try:
            values[action.dest] = _value(action, value)
        except (ValueError, TypeError, argparse.ArgumentTypeError) as e:
            parser.error(f"{where}: {key} = {value!r}: {e}")
    return values


def _dashed(options: dict[str, argparse.Action]) -> list[str]:
    return [k.replace("_", "-") for k in options]


def _value(action: argparse.Action, value: Any) -> Any:
    """A TOML value as the option would have parsed its text."""
    if getattr(action, "settings", None):  # --mpc and kin: a table, or their NAME=VALUE text
        if isinstance(value, dict):
            return ",".join(f"{k}={_setting_text(k, v)}" for k, v in value.items())
        if isinstance(value, str):
            return value
        raise ValueError("a table of NAME = value, or a NAME=VALUE,... string")
    if action.nargs == 0:  # an on/off flag
        if not isinstance(value, bool):
            raise ValueError("true or false (an on/off flag)")
        return action.const if value else action.default
    if isinstance(value, bool):
        if action.nargs == "?" and value:  # `--weather-noise` alone
            return action.const
        raise ValueError("not a boolean: this option takes a value")
    if isinstance(value, list):
        if action.type is not None or any(isinstance(v, (list, dict, bool)) for v in value):
            raise ValueError("a single value, not an array")
        value = ",".join(map(str, value))  # a comma-separated option (weathers = ["CA", "CO"])
    elif isinstance(value, dict):
        raise ValueError("a single value, not a table")
    elif not isinstance(value, (str, int, float)):
        raise ValueError("a string or a number")
    text = value if isinstance(value, str) else str(value)
    try:
        typed = action.type(text) if callable(action.type) else text
    except (ValueError, TypeError, argparse.ArgumentTypeError):
        expected = TYPE_NAMES.get(action.type, f"not a valid {getattr(action.type, '__name__', 'value')}")
        raise ValueError(expected) from None
    if action.choices is not None and typed not in action.choices:
        raise ValueError(f"one of {', '.join(map(str, action.choices))}")
    return typed


def _setting_text(key: str, value: Any) -> str:
    """One `[mpc]` table entry as `--mpc` text: true/false, none, layer sizes as 64x64."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, list) and all(isinstance(v, int) and not isinstance(v, bool) for v in value):
        return "x".join(map(str, value))  # layer sizes
    if not isinstance(value, (str, int, float)):
        raise ValueError(f"{key}: a boolean, a number, a string or layer sizes ([64, 64])")
    if isinstance(value, str) and "," in value:
        raise ValueError(f"{key}: one value, no commas")
    return str(value)
