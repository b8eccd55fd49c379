"""The settings a resumed run takes from its config.json rather than from its checkpoint.

SB3 restores an algorithm's hyperparameters from the saved model; a run resumed with the same config.json gets
the same values either way. Population-based training (experiments/tune_schedulers.py) resumes a trial from a
better trial's checkpoint with some settings perturbed: those must come from the trial's config, so `load`
is handed them (SB3 sets them before it rebuilds its schedules and buffers). These are the settings that can
change mid-run without changing the network or the buffers' sizes: the only ones PBT may mutate.
"""

from __future__ import annotations

MUTABLE = {  # config.json key -> the algorithm's attribute, per algorithm
    "trpo": {"trpo.learning_rate": "learning_rate", "trpo.target_kl": "target_kl", "trpo.gamma": "gamma",
             "trpo.gae_lambda": "gae_lambda"},
    "ppo": {"ppo.learning_rate": "learning_rate", "ppo.clip_range": "clip_range", "ppo.n_epochs": "n_epochs",
            "trpo.gamma": "gamma", "trpo.gae_lambda": "gae_lambda"},
    "sac": {"sac.learning_rate": "learning_rate", "sac.tau": "tau", "sac.gamma": "gamma"},
}  # fmt: skip
MUTABLE["mbpo"] = MUTABLE["sac"]
MUTABLE_KEYS = sorted({key for keys in MUTABLE.values() for key in keys})


def load_kwargs(cfg) -> dict:
    """The algorithm's mutable attributes from a TrainConfig, for `ALGORITHM.load(..., **load_kwargs(cfg))`."""
    out = {}
    for key, attribute in MUTABLE.get(cfg.algorithm, {}).items():
        head, _, tail = key.partition(".")
        out[attribute] = getattr(getattr(cfg, head), tail)
    return out
