"""Reinforcement-learning control of a data center's cooling against parallel EnergyPlus simulations.

Importing the package registers `parallel_eplus/DataCenter-v0` (with Gymnasium: the `train` extra); everything else
loads on first use, so the EnergyPlus-side process (which imports `parallel_eplus.buildings.datacenter`) stays small and
starts fast.
"""

import os as _os

from parallel_eplus import _moved

# onnxruntime (1.2x on Linux) writes a device id and a telemetry database under ~/.cache/Microsoft/DeveloperTools
# (or $XDG_CACHE_HOME) as it is imported, unless ORT_DISABLE_TELEMETRY is set by then: set here, before anything of
# the package imports it, so a served controller writes nowhere but its log (a user's own setting is kept).
_os.environ.setdefault("ORT_DISABLE_TELEMETRY", "1")

_moved.install()  # module paths from before 1.1 import, with a DeprecationWarning, until 2.0

ENV_ID = "parallel_eplus/DataCenter-v0"

BUILDING_ENV_ID = "parallel_eplus/Building-v0"  # the same env; pass building=SPEC

ENGINE_SIDE = "PARALLEL_EPLUS_ENGINE_SIDE"  # set for the EnergyPlus-side process (episodes/process.py): no env

if not _os.environ.get(ENGINE_SIDE):  # Gymnasium would cost that process ~50 ms of start-up per worker (issue 39)
    try:  # a controller server's install (`pip install parallel-eplus[serve]`) has no Gymnasium and needs no env
        from gymnasium.envs.registration import register, registry
    except ModuleNotFoundError:
        pass
    else:
        for _id in (ENV_ID, BUILDING_ENV_ID):
            if _id not in registry:
                register(id=_id, entry_point="parallel_eplus.envs.env:EnergyPlusEnv", disable_env_checker=True)

_LAZY = {
    "EnergyPlusEnv": "envs.env",
    "EnergyPlusError": "errors",
    "ProtocolError": "errors",
    "RewardConfig": "buildings.scoring.reward",
}


def __getattr__(name: str):
    if name == "__version__":  # pyproject.toml's, as installed (importlib.metadata costs the EnergyPlus side nothing)
        from importlib.metadata import version

        return version("parallel-eplus")
    if name in _LAZY:
        import importlib

        return getattr(importlib.import_module(f".{_LAZY[name]}", __name__), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


__all__ = ["ENV_ID", *_LAZY]
