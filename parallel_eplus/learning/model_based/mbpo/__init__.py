"""`train --algorithm mbpo`: SAC on real and model transitions (`algorithm.py`), its replay buffer (`buffer.py`) and the
ensemble state it starts from (`state.py`).
"""


def __getattr__(name: str):  # the names of the module that had this path before 1.1, kept until 2.0
    from parallel_eplus._moved import forward

    return forward(__name__, name)
