"""Which learner an `--algorithm` name means: SB3's algorithms, the on-policy ones with the numpy rollout loop.

The model-based planner (`mpc`) is not here: it is not an SB3 algorithm (learning/model_based/).
"""

from __future__ import annotations

from sb3_contrib import TRPO
from stable_baselines3 import PPO

from parallel_eplus.learning.guarded_sac import GuardedSAC
from parallel_eplus.learning.rollout import NumpyRollouts


class FastTRPO(NumpyRollouts, TRPO):
    """sb3-contrib's TRPO (the paper's algorithm) with the numpy rollout loop."""


class FastPPO(NumpyRollouts, PPO):
    """Stable-Baselines3's PPO with the numpy rollout loop: the comparison the paper did not run."""


# SAC is off-policy: SB3's own step-by-step collect_rollouts feeds its replay buffer (GuardedSAC: SB3's SAC with the
# mbpo rail's guard and a cloned actor's warm-up).
ALGORITHMS: dict[str, type] = {"trpo": FastTRPO, "ppo": FastPPO, "sac": GuardedSAC, "mbpo": GuardedSAC}
