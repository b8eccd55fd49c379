"""Model-based control (`train --algorithm mpc`): learn the building, then plan on the model.

dataset.py (transitions and their features), exogenous.py (the weather file and the clock as a forecast),
dynamics.py (the ensemble), planner.py (CEM over bounded action increments), agent.py (the Dyna loop in the
service), controller.py (the planner as a controller `evaluate` runs), distill.py (the planner into a policy).
"""
