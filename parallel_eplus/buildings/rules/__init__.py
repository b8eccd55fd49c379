"""Rule-based controllers, the references a learned controller must beat: the data center's rule (`datacenter.py`),
Guideline 36's supply-air reset (`air_reset.py`), the own schedules with a margin (`own_margin.py`), pre-cooling for
a tariff's peak (`precool.py`), outdoor air on demand alone (`on_demand.py`), and a rule's settings from a spec
(`settings.py`).
"""
