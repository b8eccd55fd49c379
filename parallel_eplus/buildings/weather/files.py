"""The paper's five weather files by short code, the other climates the EnergyPlus wheel ships by city, or any
.epw by path."""

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
# The wheel's other eleven (pyenergyplus/data/weather/, TMY3), by city: `evaluate --weathers all` runs all 16.
CLIMATES: dict[str, str] = {
    "Phoenix": "USA_AZ_Phoenix-Sky.Harbor.Intl.AP.722780_TMY3.epw",
    "LasVegas": "USA_NV_Las.Vegas-McCarran.Intl.AP.723860_TMY3.epw",
    "Fresno": "USA_CA_Fresno.Air.Terminal.723890_TMY3.epw",
    "Miami": "USA_FL_Miami.Intl.AP.722020_TMY3.epw",
    "Orlando": "USA_FL_Orlando.Intl.AP.722050_TMY3.epw",
    "OklahomaCity": "USA_OK_Oklahoma.City-Will.Rogers.World.AP.723530_TMY3.epw",
    "Newark": "USA_NJ_Newark.Intl.AP.725020_TMY3.epw",
    "Champaign": "USA_IL_University.of.Illinois-Willard.AP.725315_TMY3.epw",
    "Denver": "USA_CO_Denver-Aurora-Buckley.AFB.724695_TMY3.epw",
    "Boulder": "USA_CO_Boulder-Broomfield-Jefferson.County.AP.724699_TMY3.epw",
    "ColoradoSprings": "USA_CO_Colorado.Springs-Peterson.Field.724660_TMY3.epw",
}
# The paper's five by city too ("Chicago" is IL), and every name without spaces, dots or case ("las vegas").
ALIASES = {"SanFrancisco": "CA", "Golden": "CO", "Tampa": "FL", "Chicago": "IL", "Sterling": "VA", "Dulles": "VA"}
ALL_WEATHERS: tuple[str, ...] = (*WEATHER_FILES, *CLIMATES)


def _key(text: str) -> str:
    return "".join(ch for ch in text.lower() if ch.isalnum())


_NAMES = {_key(n): n for n in (*WEATHER_FILES, *CLIMATES)} | {_key(a): code for a, code in ALIASES.items()}


def short_name(weather: str | Path) -> str | None:
    """The canonical short name (CA, ..., Phoenix, ...) a text names, or None."""
    return _NAMES.get(_key(str(weather))) if not str(weather).lower().endswith(".epw") else None


def resolve_weather(weather: str | Path) -> Path:
    """A code (CA, CO, FL, IL, VA) or a path to an .epw file; fails before anything is spawned."""
    text = str(weather)
    name = short_name(text)
    if name is not None:
        return weather_file(WEATHER_FILES.get(name) or CLIMATES[name])
    if text.lower().endswith(".epw"):
        path = Path(text).expanduser()
    else:
        raise ValueError(
            f"unknown weather {text!r}: use a short name ({', '.join(ALL_WEATHERS)}), 'all', or a path to an .epw file"
        )
    if not path.is_file():
        raise FileNotFoundError(f"weather file not found: {path}")
    with open(path, "rb") as f:
        if not f.read(12).removeprefix(b"\xef\xbb\xbf").upper().startswith(b"LOCATION"):
            raise ValueError(f"{path} is not an EnergyPlus weather file (an .epw starts with a LOCATION line)")
    return path.resolve()


def weather_label(weather: str | Path) -> str:
    """Short label for logs and records: the code, or the file's stem."""
    return short_name(weather) or Path(str(weather)).stem


def parse_weathers(spec: str, known: Mapping[str, Path] | None = None) -> list[str]:
    """'CA,CO,FL' -> ['CA', 'CO', 'FL'], each checked; 'all': the 16 the wheel ships (`ALL_WEATHERS`);
    `known`: a building spec's own short names."""
    items = [w.strip() for w in spec.split(",") if w.strip()]
    if [w.lower() for w in items] == ["all"]:
        return list(ALL_WEATHERS)
    if not items:
        raise ValueError("no weather given")
    for w in items:
        if w not in (known or {}):
            resolve_weather(w)
    return items
