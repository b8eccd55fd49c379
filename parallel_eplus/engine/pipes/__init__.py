"""The wire between the env and an EnergyPlus process: a private pair of named pipes (`pipe.py`) carrying float
frames (`frames.py`), when a side spins for its next frame (`spin.py`), what a killed run left behind
(`leftovers.py`) and the simulations closed at interpreter exit (`at_exit.py`).
"""
