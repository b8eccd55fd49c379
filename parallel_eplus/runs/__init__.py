"""A run on disk: its folder's names and files, its status, atomic checkpoints, observation statistics, policy files
(loaded without unpickling), a saved policy acting in numpy, and the registry of every run.

May import engine and buildings; nothing that learns or evaluates.
"""
