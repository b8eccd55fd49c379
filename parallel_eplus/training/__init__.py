"""One training run, assembled: its settings (`TrainConfig`), `train` (workers, learner, callbacks, checkpoints) and
the TensorBoard episode metrics.

May import learning, evaluation, envs, runs, engine and buildings; not experiments, bench or cli.
"""
