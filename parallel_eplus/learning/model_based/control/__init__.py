"""Model predictive control in training and `evaluate`: the controller over every worker (`mpc.py`), its checkpoints
(`checkpoint.py`) and a saved planner run as a controller (`saved_planner.py`). Its settings are
`model_based/settings.py`'s; the planner itself is the runtime's (`runtime/planner.py`).
"""


def __getattr__(name: str):  # the names of the module that had this path before 1.1, kept until 2.0
    from parallel_eplus._moved import forward

    return forward(__name__, name)
