"""`parallel-eplus export`: a trained policy as an ONNX graph (`policy.py`, `graph.py`), a planner as files `serve` runs
(`planner.py`), and the replay that checks an export against `evaluate` (`parity.py`).
"""


def __getattr__(name: str):  # the names of the module that had this path before 1.1, kept until 2.0
    from parallel_eplus._moved import forward

    return forward(__name__, name)
