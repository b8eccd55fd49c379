"""BACnet/IP with BAC0 (the `bacnet` extra): the application both ends share (`app.py`), an EnergyPlus episode as a
device (`device.py`), an exported controller as a supervisor (`supervisor.py`, `planner.py`) and where each point
lives (`point_map.py`).
"""


def __getattr__(name: str):  # the names of the module that had this path before 1.1, kept until 2.0
    from parallel_eplus._moved import forward

    return forward(__name__, name)
