"""The paper's five weather files by short code, or any .epw by path."""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path

from parallel_eplus.buildings.resources import weather_file

# Paper, Section 5.1.2. The files come from the pyenergyplus-lbnl wheel (TMY3); see resources.py.
WEATHER_FILES: dict[str, str] = {
    "CA": "USA_CA_San.Francisco.Intl.AP.724940_TMY3.epw",
    "CO": "USA_CO_Golden-NREL.724666_TMY3.epw",
    "FL": "USA_FL_Tampa.Intl.AP.722110_TMY3.epw",
    "IL": "USA_IL_Chicago-OHare.Intl.AP.725300_TMY3.epw",
    "VA": "USA_VA_Sterling-Washington.Dulles.Intl.AP.724030_TMY3.epw",
}


def resolve_weather(weather: str | Path) -> Path:
    """A code (CA, CO, FL, IL, VA) or a path to an .epw file; fails before anything is spawned."""
    text = str(weather)
    if text.upper() in WEATHER_FILES:
        return weather_file(WEATHER_FILES[text.upper()])
    if text.lower().endswith(".epw"):
        path = Path(text).expanduser()
    else:
        raise ValueError(f"unknown weather {text!r}: use a code ({', '.join(WEATHER_FILES)}) or a path to an .epw file")
    if not path.is_file():
        raise FileNotFoundError(f"weather file not found: {path}")
    with open(path, "rb") as f:
        if not f.read(12).removeprefix(b"\xef\xbb\xbf").upper().startswith(b"LOCATION"):
            raise ValueError(f"{path} is not an EnergyPlus weather file (an .epw starts with a LOCATION line)")
    return path.resolve()


def weather_label(weather: str | Path) -> str:
    """Short label for logs and records: the code, or the file's stem."""
    text = str(weather)
    return text.upper() if text.upper() in WEATHER_FILES else Path(text).stem


def parse_weathers(spec: str, known: Mapping[str, Path] | None = None) -> list[str]:
    """'CA,CO,FL' -> ['CA', 'CO', 'FL'], each checked; `known`: a building spec's own short names."""
    items = [w.strip() for w in spec.split(",") if w.strip()]
    if not items:
        raise ValueError("no weather given")
    for w in items:
        if w not in (known or {}):
            resolve_weather(w)
    return items
