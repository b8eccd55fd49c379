"""What runs inside the EnergyPlus process (`python -m parallel_eplus.engine.eplus_side.callback`): the API runtime
callback (`callback.py`), one control step in Python (`bridge.py`) or in C (`eplus_callback.c` via `native.py`,
`handoff.py`), and the parked template that forks episodes (`fork.py`). It imports nothing of the learner's.
"""
