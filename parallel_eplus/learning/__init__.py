"""How a controller learns: the algorithms' settings, rollout collection (local workers pipelined, or Ray actors each
collecting a fragment), the comfort constraint (Lagrangian), imitation of the building's own controls. A new
algorithm (the model-based planner too) goes here.

May import evaluation, envs, runs, engine and buildings; not training or above.
"""
