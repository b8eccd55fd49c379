"""How a building is scored: the paper's reward (`reward.py`), comfort and energy per step and episode (`comfort.py`),
BOPTEST's KPIs (`kpis.py`).
"""
