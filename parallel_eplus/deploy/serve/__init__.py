"""What the `serve` extra runs, with no torch or EnergyPlus (import-linter forbids both): the contract (`contract.py`),
a policy or planner answering one request (`runtime.py`, `planner_runtime.py`, `served_rule.py`) and the HTTP server
(`server.py`).
"""
