"""Where a worker's episodes come from: one EnergyPlus process behind one pipe pair, spawned and stopped with nothing
left behind (`process.py`), long-lived EnergyPlus-side processes (`warm.py`), episodes forked from a parked
template (`fork.py`), the next episode prepared while one runs (`prepared.py`), and the supply that chooses among
them (`supply.py`).
"""
