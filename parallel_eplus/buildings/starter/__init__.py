"""`parallel-eplus building init`: a starter spec from any EnergyPlus model, from a survey of what it offers
(`survey.py`) to the TOML text it writes (`write.py`, `air_side.py`, `toml_text.py`).
"""
