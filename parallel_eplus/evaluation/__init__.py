"""Fixed controllers scored on weathers: the built-in controls, the rule-based controller or a frozen policy, run
episode by episode (locally or as Ray tasks), then tables, figures and intervals over seeds.

Learning and training use it too (imitation records the built-in controls with it). May import envs, runs, engine
and buildings; not learning or above.
"""
