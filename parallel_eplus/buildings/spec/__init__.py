"""A building spec: the TOML file read section by section (`load.py`, `sections.py`) into plain frozen records
(`records.py`). Resolving it against the model is `buildings/building.py`'s; checking it, `buildings/check/`'s.
"""

from parallel_eplus.buildings.spec.load import load_spec
from parallel_eplus.buildings.spec.records import BuildingSpec, SpecError

__all__ = ["BuildingSpec", "SpecError", "load_spec"]


def __getattr__(name: str):  # the names of the module that had this path before 1.1, kept until 2.0
    from parallel_eplus._moved import forward

    return forward(__name__, name)
