"""Weather: EPW files by code, city or path (`files.py`), the EPW table (`epw.py`), per-episode noise (`noise.py`), and
forecasts, as observations (`forecast_features.py`) and as the planner's source (`forecast.py`).
"""


def __getattr__(name: str):  # the names of the module that had this path before 1.1, kept until 2.0
    from parallel_eplus._moved import forward

    return forward(__name__, name)
