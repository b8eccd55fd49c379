"""Which optional extra (pyproject.toml) a command needs, read from the installed package's metadata, so a command
run in a lighter install (a controller server's `[serve]`) stops with one line naming what to install."""

from __future__ import annotations

import importlib.util
import re
from importlib import metadata

# 'torch==2.13.0; extra == "train"', 'parallel-eplus[train]; extra == "export"'
REQUIREMENT = re.compile(r"\s*([A-Za-z0-9_.-]+)\s*(?:\[([^\]]*)\])?[^;]*;.*extra\s*==\s*[\"'](\w+)[\"']")
PACKAGE = "parallel-eplus"
IMPORT_NAMES = {"bac0": "BAC0"}  # distributions imported by another name than theirs lower-cased


def _module(distribution: str) -> str:
    """The import name of a distribution we depend on (pyenergyplus-lbnl installs `pyenergyplus`)."""
    name = distribution.lower().replace("-", "_").removesuffix("_lbnl")
    return IMPORT_NAMES.get(name, name)


def _requirements() -> list[tuple[str, list[str], str]]:
    """(distribution, its extras, our extra that asks for it) for every optional requirement; [] when the package
    is not installed (a bare source tree), so nothing is checked."""
    try:
        lines = metadata.requires(PACKAGE) or []
    except metadata.PackageNotFoundError:
        return []
    found = (REQUIREMENT.match(line) for line in lines)
    return [(m[1], [e.strip() for e in (m[2] or "").split(",") if e.strip()], m[3]) for m in found if m]


def modules(extra: str, seen: frozenset[str] = frozenset()) -> list[str]:
    """The top-level modules `extra` installs, through the extras it includes (`export` includes `train`)."""
    out: list[str] = []
    for distribution, extras, wanted_by in _requirements():
        if wanted_by != extra:
            continue
        if distribution.lower() == PACKAGE:
            for included in set(extras) - seen - {extra}:
                out += modules(included, seen | {extra})
        else:
            out.append(_module(distribution))
    return list(dict.fromkeys(out))


def missing(extra: str | None) -> str | None:
    """The first module of `extra` that is not installed, or None (found without importing anything)."""
    return next((m for m in modules(extra) if importlib.util.find_spec(m) is None), None) if extra else None


def extra_for(module: str) -> str | None:
    """The extra whose distribution provides `module` (the first listed), or None."""
    top = module.split(".")[0]
    return next((wanted_by for d, _, wanted_by in _requirements() if _module(d) == top), None)


def install_hint(module: str, extra: str) -> str:
    return f"{module} is not installed: pip install '{PACKAGE}[{extra}]' (scripts/setup.sh installs every extra)"
