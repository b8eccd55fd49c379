"""Reinforcement-learning control of a data center's cooling against parallel EnergyPlus simulations."""

from gymnasium.envs.registration import register, registry

from .env import EnergyPlusEnv
from .errors import EnergyPlusError, ProtocolError
from .reward import RewardConfig

ENV_ID = "parallel_eplus/DataCenter-v0"

if ENV_ID not in registry:
    register(id=ENV_ID, entry_point="parallel_eplus.env:EnergyPlusEnv", disable_env_checker=True)

__all__ = ["ENV_ID", "EnergyPlusEnv", "EnergyPlusError", "ProtocolError", "RewardConfig"]
