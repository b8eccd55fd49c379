"""The controller's copy of a building's EnergyPlus model: the IDF's objects read (`objects.py`), the copy prepared for
a run (`prepare.py`), node setpoints taken from the model's setpoint managers (`takeover.py`), outdoor air on demand
(`ventilation.py`), what the model says of its loops and thermostats (`loops.py`, `thermostat.py`).
"""
