"""The oracle (issue 89): a planner that plans on EnergyPlus itself. At each decision it forks the running episode
(engine/episodes/branch.py), plays candidate action sequences over its horizon in the copies, with the true weather
and the building's true response, scores them with the learned planner's cost, comfort term and action limits
(learning/model_based/runtime/planner.py) and applies the best one's first hour. `evaluate --oracle`.

May import what learning may (evaluation, envs, runs, engine, buildings) and learning/model_based/runtime.
"""
