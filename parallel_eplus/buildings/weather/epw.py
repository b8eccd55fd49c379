"""An EnergyPlus weather file (.epw) as a table: 8 header lines, then one comma-separated row per record.

Read with pandas for the numbers; rewritten field by field (`replace_columns`), so every column we do not
change stays byte for byte what EnergyPlus read before (the data-source flags, the missing-value codes).
"""

from __future__ import annotations

import io
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    import pandas as pd

HEADER_LINES = 8
# The 35 fields of a data row, EnergyPlus's Auxiliary Programs "EPW data dictionary", short names as Sinergym's.
COLUMNS = (
    "year", "month", "day", "hour", "minute", "source_flags", "drybulb", "dewpoint", "relhum", "atmos_pressure",
    "exthorrad", "extdirrad", "horirsky", "glohorrad", "dirnorrad", "difhorrad", "glohorillum", "dirnorillum",
    "difhorillum", "zenlum", "winddir", "windspd", "totskycvr", "opaqskycvr", "visibility", "ceiling_hgt",
    "presweathobs", "presweathcodes", "precip_wtr", "aerosol_opt_depth", "snowdepth", "days_last_snow", "albedo",
    "liq_precip_depth", "liq_precip_rate",
)  # fmt: skip
# The columns this package writes, with the decimals EnergyPlus's own weather converter gives them.
DECIMALS = {"drybulb": 1, "dewpoint": 1, "relhum": 0, "dirnorrad": 0, "difhorrad": 0, "glohorrad": 0}


def column_index(name: str) -> int:
    """A column's position in a data row, or a ValueError listing the names."""
    try:
        return COLUMNS.index(name)
    except ValueError:
        raise ValueError(f"unknown EPW column {name!r}: use one of {', '.join(COLUMNS[6:])}") from None


def read_epw(path: str | Path) -> tuple[list[str], pd.DataFrame]:
    """(the 8 header lines, the records as a DataFrame with `COLUMNS`)."""
    import pandas as pd  # here: specs (which name columns) load in the EnergyPlus-side process, without pandas

    text = Path(path).read_text(encoding="latin-1")
    lines = text.splitlines(keepends=True)
    if len(lines) <= HEADER_LINES or not lines[0].upper().startswith("LOCATION"):
        raise ValueError(f"{path} is not an EnergyPlus weather file (an .epw starts with 8 header lines)")
    body = "".join(lines[HEADER_LINES:])
    data = pd.read_csv(io.StringIO(body), header=None, names=list(COLUMNS), dtype={"source_flags": str,
                       "presweathcodes": str}, keep_default_na=False)  # fmt: skip
    return lines[:HEADER_LINES], data


def records_per_hour(header: list[str]) -> int:
    """The DATA PERIODS line's records per hour (1 for TMY3 files)."""
    fields = header[HEADER_LINES - 1].split(",")
    try:
        return int(fields[2]) if fields[0].strip().upper() == "DATA PERIODS" else 1
    except (IndexError, ValueError):
        return 1


def replace_columns(source: str | Path, target: str | Path, values: dict[str, np.ndarray]) -> None:
    """Write `source` to `target` with the named columns' fields replaced (formatted with `DECIMALS`);
    header lines, line endings and every other field are copied unchanged."""
    lines = Path(source).read_text(encoding="latin-1").splitlines(keepends=True)
    rows = lines[HEADER_LINES:]
    formatted = {}
    for name, v in values.items():
        if len(v) != len(rows):
            raise ValueError(f"{name}: {len(v)} values for {len(rows)} records")
        d = DECIMALS.get(name, 1)
        formatted[column_index(name)] = [f"{x:.{d}f}" if d else str(int(round(x))) for x in v]
    out = lines[:HEADER_LINES]
    for k, line in enumerate(rows):
        body = line.rstrip("\r\n")
        fields = body.split(",")
        for i, texts in formatted.items():
            fields[i] = texts[k]
        out.append(",".join(fields) + line[len(body) :])
    Path(target).write_text("".join(out), encoding="latin-1")
