"""The Gymnasium side: `EnergyPlusEnv` (one worker), `EnergyPlusVectorEnv` (N workers stepped together or each as
it answers) and joining a Ray cluster with the package shipped.

May import runs, engine and buildings; not evaluation, learning or above.
"""
