"""The TOML text `building init` writes: strings, numbers, commented [[actions]] candidates (init.py, init_air.py)."""

from __future__ import annotations

import json
import re
from pathlib import Path


def snake(text: str) -> str:
    return re.sub(r"[^a-z0-9]+", "_", text.lower()).strip("_")


def toml_str(text: str | Path) -> str:
    return json.dumps(str(text))  # a TOML basic string


def num(x: float) -> str:
    text = f"{x:.6g}"
    return text + ".0" if text.lstrip("-").isdigit() else text


def seen_text(v: tuple[float, float] | None, unit: str = "C") -> str:
    return f" (seen {v[0]:.1f}..{v[1]:.1f} {unit})" if v else ""


def clamp(x: float, low: float, high: float) -> float:
    return round(min(max(x, low), high), 2)


def candidate(name, component, control, key, low, high, initial, unit, note, readback=None) -> list[str]:
    """One commented [[actions]] block; `key` may be a list (one action moving several actuators together); `note`
    one line, or several: the first above the block, the others inside it as comments, so that uncommenting the
    block (removing "# " from every line after the first) leaves valid TOML; `readback`: (variable, key) where the
    building's own choice can be read back."""
    notes = note if isinstance(note, list) else [note]
    lines = [f"# {notes[0]}", "# [[actions]]", *(f"# # {n}" for n in notes[1:])]
    lines += [f"# name = {toml_str(name)}", f'# unit = "{unit}"']
    lines += [f"# low = {num(low)}", f"# high = {num(high)}", f"# initial = {num(initial)}"]
    one = "{{ component = {}, control = {}, key = {} }}"
    if isinstance(key, list):
        lines.append("# actuators = [")
        lines += [f"#   {one.format(toml_str(component), toml_str(control), toml_str(k))}," for k in key]
        lines.append("# ]")
    else:
        lines.append(f"# actuators = [{one.format(toml_str(component), toml_str(control), toml_str(key))}]")
    if readback:
        lines.append(f"# readback = {{ variable = {toml_str(readback[0])}, key = {toml_str(readback[1])} }}")
    return [*lines, ""]
