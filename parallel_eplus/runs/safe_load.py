"""A saved SB3 policy network, rebuilt from the readable part of model.zip: nothing in the file is unpickled.

SB3 stores a model's classes, spaces and schedules as cloudpickle inside `data` (its `load` unpickles them,
which runs whatever code the file's author put there) and the weights as tensors (read with
`weights_only=True`). For acting, the policy's class, network shape and spaces are enough, and `data` keeps a
readable copy of each: they are rebuilt here from an allow-list of classes, and the weights loaded into them.
"""

from __future__ import annotations

import json
import zipfile
from pathlib import Path

import numpy as np
import torch as th
from gymnasium import spaces
from stable_baselines3.common.save_util import load_from_zip_file

POLICY_CLASSES = {  # the policy module SB3 records -> the MLP policy class we train with
    "stable_baselines3.common.policies": "stable_baselines3.common.policies:ActorCriticPolicy",
    "stable_baselines3.sac.policies": "stable_baselines3.sac.policies:SACPolicy",
}
ACTIVATIONS = {f"<class 'torch.nn.modules.activation.{n}'>": getattr(th.nn, n) for n in ("Tanh", "ReLU", "ELU")}


def _class(spec: str):
    import importlib

    module, name = spec.split(":")
    return getattr(importlib.import_module(module), name)


def _box(item: dict, where: str) -> spaces.Box:
    shape, dtype = tuple(item["_shape"]), np.dtype(item.get("dtype", "float32"))
    bounds = []
    for key in ("low", "high"):
        values = np.array(item[key].replace("\n", " ").strip("[]").split(), dtype=float)
        if values.size != int(np.prod(shape)):
            raise ValueError(f"{where}: unreadable {key} bounds")
        bounds.append(values.reshape(shape).astype(dtype))
    return spaces.Box(bounds[0], bounds[1], dtype=dtype)


def _no_optimizer(params, lr, **kwargs) -> None:
    """Acting needs no optimizer, and building one imports torch._dynamo (about 2 s of CPU a process)."""
    return None


def load_policy_network(model_zip: Path):
    """The policy of a saved model, in evaluation mode, built without unpickling anything from the file."""
    try:
        with zipfile.ZipFile(model_zip) as z:
            data = json.loads(z.read("data"))
        module = data["policy_class"]["__module__"]
        kwargs_item = data["policy_kwargs"]
        obs_space = _box(data["observation_space"], f"{model_zip} observation space")
        act_space = _box(data["action_space"], f"{model_zip} action space")
    except (zipfile.BadZipFile, KeyError, TypeError, AttributeError, ValueError) as e:
        raise ValueError(f"{model_zip}: not a saved policy we can read safely ({type(e).__name__}: {e})") from None
    if module not in POLICY_CLASSES:
        raise ValueError(f"{model_zip}: policy class from {module!r} is not one parallel-eplus trains")
    kwargs = {}
    for key, value in kwargs_item.items():
        if key in (":type:", ":serialized:", "optimizer_kwargs", "optimizer_class"):
            continue  # the optimizer does not act
        if key == "activation_fn":
            if value not in ACTIVATIONS:
                raise ValueError(f"{model_zip}: activation {value} is not one parallel-eplus uses")
            value = ACTIVATIONS[value]
        elif isinstance(value, str):
            raise ValueError(f"{model_zip}: policy setting {key} is stored only as code ({value[:60]})")
        kwargs[key] = value
    # Every cloudpickled entry is replaced by None, so SB3 reads only the JSON and the weights (weights_only).
    serialized = {k: None for k, v in data.items() if isinstance(v, dict) and ":serialized:" in v}
    _, params, _ = load_from_zip_file(model_zip, device="cpu", custom_objects=serialized)
    if data.get("use_sde") is True and module == "stable_baselines3.common.policies":
        kwargs["use_sde"] = True  # gSDE's exploration parameters: a matrix of log-stds (acting ignores them)
    policy = _class(POLICY_CLASSES[module])(
        obs_space, act_space, lambda _: 0.0, optimizer_class=_no_optimizer, **kwargs
    )
    try:
        policy.load_state_dict(params["policy"])
    except (RuntimeError, KeyError) as e:
        raise ValueError(f"{model_zip}: its weights do not fit its recorded network ({e})") from None
    policy.set_training_mode(False)
    return policy
