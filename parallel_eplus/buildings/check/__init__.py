"""`parallel-eplus building check`: every name in a spec resolved against the model before any training step
(`names.py`), and the proof that each node-setpoint action reaches its node (`reach.py`).
"""


def __getattr__(name: str):  # the names of the module that had this path before 1.1, kept until 2.0
    from parallel_eplus._moved import forward

    return forward(__name__, name)
