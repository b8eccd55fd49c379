"""The planner's settings renamed in 1.1, and their old names and values kept for one release.

"own" meant several things among the planner's settings; now one word names one thing. The **baseline** is the plan
the planner is measured against: what the building's own controls set (`evaluate --baseline` runs the same), with
`baseline_source = "rule"` the spec's rule riding them (`evaluate --rbc`). The **band** is the comfort band.

`RENAMED` is the one table of renames. Every entry where settings arrive reads it: `--mpc`, `evaluate --planner` and
`export --planner-options` text (`FromText.from_text`), a run's config.json, a planner checkpoint or planner.pt
(`MPCSettings.of_saved`), an exported contract's settings (`PlannerSettings.of`, the served planner), the presets and
sweep specs (through `--mpc` text). An old name or value still works and warns, once per process, naming the new
one: a `DeprecationWarning`, and a logged WARNING for the command line. New files are written with the new names.
2.0 removes the old ones. Numpy-free and torch-free: the served planner reads it.
"""

from __future__ import annotations

import logging
import warnings
from collections.abc import Mapping
from typing import Any

log = logging.getLogger(__name__)

REMOVED_IN = "2.0"

# old setting name: (new name, {old value: new value}); a name kept when only its values change.
RENAMED: dict[str, tuple[str, dict[str, str]]] = {
    "own_plan": ("baseline_source", {}),
    "comfort_reference": ("comfort_reference", {"bound": "band", "own": "baseline"}),
    "comfort_level": ("comfort_level", {"own": "baseline"}),
    "band_thermostats": ("band_thermostats", {"at_least_own": "at_least_baseline", "own": "baseline"}),
    "own_radius": ("baseline_radius", {}),
    "own_margin": ("baseline_margin", {}),
}

_logged: set[str] = set()  # the old names and values the log has named (once each per process)


def renamed(name: str, value: Any, where: str = "--mpc") -> tuple[str, Any]:
    """(name, value) as they are called now; an old name or value warns, naming its new one. `where`: the entry
    the setting came through, for the message (`--mpc`, a file's path)."""
    if name not in RENAMED:
        return name, value
    new, values = RENAMED[name]
    new_value = values.get(value, value) if isinstance(value, str) else value
    if new != name:
        _warn(f"{where}: the setting {name} is now {new}", name)
    if new_value != value:
        _warn(f"{where}: {new}={value} is now {new}={new_value}", f"{new}={value}")
    return new, new_value


def renamed_settings(values: Mapping[str, Any], where: str) -> dict[str, Any]:
    """A saved mapping of settings (config.json's `mpc`, a checkpoint's, a contract's) with today's names and values;
    where an old name and its new one are both given, the new one counts."""
    out: dict[str, Any] = {}
    for name, value in values.items():
        new, new_value = renamed(name, value, where)
        if new == name or new not in values:
            out[new] = new_value
    return out


def _warn(message: str, key: str) -> None:
    message += f" (the old one is accepted until {REMOVED_IN})"
    warnings.warn(message, DeprecationWarning, stacklevel=4)
    if key not in _logged:
        _logged.add(key)
        log.warning("%s", message)
