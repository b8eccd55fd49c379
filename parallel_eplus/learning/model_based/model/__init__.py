"""The learned model of a building: its data (`dataset.py`), where they come from (`sources.py`), its weather inputs
(`exogenous.py`), the torch ensemble (`dynamics.py`), and the own controls' comfort level it learns from
(`own_level.py`).
"""
