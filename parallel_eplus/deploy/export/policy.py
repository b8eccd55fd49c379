"""`parallel-eplus export RUN_OR_MODEL -o DIR`: a trained policy as controller.onnx and its contract, controller.json.

The graph holds every step between readings and setpoints (graph.py); the contract every fact a building's
management system needs to call it (contract.py). Before anything is written the graph is checked with
onnxruntime against the policy as `evaluate` runs it, on observations drawn around the training statistics.
"""

from __future__ import annotations

import datetime as dt
import hashlib
import json
import logging
from pathlib import Path

import numpy as np

from parallel_eplus import io
from parallel_eplus.buildings.building import load_building
from parallel_eplus.buildings.crossing import thermostat_pairs, uncrossed
from parallel_eplus.buildings.datacenter import SCHEDULE_FEATURES, TIME_FEATURES, it_load_schedule
from parallel_eplus.buildings.resources import saved_building
from parallel_eplus.deploy.export.graph import INPUT, OPSET, OUTPUT, Layer, PolicyArrays, build_model
from parallel_eplus.deploy.serve.contract import CONTRACT_FILE, FORMAT, ONNX_FILE, output_entries, sensor_entries
from parallel_eplus.engine.actions import scale_action

log = logging.getLogger(__name__)

PARITY_TOLERANCE = 1e-5  # physical units: the most a setpoint may differ from the in-process policy's


def model_file(path: Path) -> Path:
    """A model.zip, a checkpoint .zip, or a run folder (its model.zip)."""
    path = Path(path)
    if path.is_dir():
        path = path / "model.zip"
    if not path.is_file():
        raise FileNotFoundError(f"no trained policy at {path}: give a run folder or its model.zip")
    return path


def run_settings(model_zip: Path) -> dict:
    from parallel_eplus.runs.policy_files import run_dir_of

    config = run_dir_of(model_zip) / "config.json"
    return json.loads(config.read_text()) if config.is_file() else {}


def _refuse_unexportable(model_zip: Path, saved: dict) -> None:
    if float(saved.get("residual_scale", 0.0)) and saved.get("residual_space") == "builtin":
        raise ValueError(
            f"{model_zip}: this policy corrects the building's own setpoint schedules (train --residual "
            f"{saved['residual_scale']} --residual-space builtin): its output is a correction to add to them at each "
            "step, which the deployment contract does not carry yet; run it with `evaluate --policy`"
        )
    if float(saved.get("residual_scale", 0.0)):
        raise ValueError(
            f"{model_zip}: this policy corrects the rule-based controller (train --residual "
            f"{saved['residual_scale']}, {saved.get('residual_space', 'action')} space), whose integral state and "
            "clock live outside the network, so an ONNX file alone cannot act as it does; export a policy trained "
            "without --residual, or run it with `evaluate --policy`"
        )
    if int(saved.get("forecast_hours", 0)):
        raise ValueError(
            f"{model_zip}: this policy observes {saved['forecast_hours']} hours of weather forecast "
            "(train --forecast); "
            "a deployed controller would need them from the building's forecast service as inputs, which the contract "
            "does not describe yet: export a policy trained without --forecast"
        )
    if saved.get("model", "temp_fan") != "temp_fan" and not saved.get("building"):
        raise ValueError(f"{model_zip}: trained on model {saved['model']!r}; export takes temp_fan or a building spec")


def _stack(module, where: str) -> list[Layer]:
    """A Linear/activation stack as `Layer`s; anything else is refused by name."""
    import torch as th

    leaves = [m for m in module.modules() if not list(m.children())]
    layers = []
    for m in leaves:
        if type(m) is th.nn.Linear:
            bias = m.bias.detach().double().numpy() if m.bias is not None else np.zeros(m.out_features)
            layers.append(Layer("dense", m.weight.detach().double().numpy().T.copy(), bias.copy()))
        elif type(m) in (th.nn.Tanh, th.nn.ReLU):
            layers.append(Layer(type(m).__name__.lower()))
        elif type(m) is th.nn.ELU:
            layers.append(Layer("elu", params={"alpha": float(m.alpha)}))
        elif type(m) is th.nn.Hardtanh:
            layers.append(Layer("hardtanh", params={"min": float(m.min_val), "max": float(m.max_val)}))
        elif type(m) is th.nn.Flatten:
            continue
        else:
            raise ValueError(f"{where}: layer {type(m).__name__} cannot be exported (a linear/tanh/relu/elu MLP can)")
    return layers


def policy_layers(policy, where: str) -> tuple[list[Layer], bool]:
    """The deterministic actor of a TRPO/PPO (`ActorCriticPolicy`) or SAC (`SACPolicy`) policy: (layers, squash)."""
    from stable_baselines3.common.policies import ActorCriticPolicy
    from stable_baselines3.common.torch_layers import FlattenExtractor
    from stable_baselines3.sac.policies import SACPolicy

    if isinstance(policy, SACPolicy):
        actor = policy.actor
        if type(actor.features_extractor) is not FlattenExtractor:
            raise ValueError(f"{where}: a custom features extractor cannot be exported")
        return _stack(actor.latent_pi, where) + _stack(actor.mu, where), True
    if isinstance(policy, ActorCriticPolicy):
        if type(policy.pi_features_extractor) is not FlattenExtractor or policy.squash_output:
            raise ValueError(f"{where}: a custom features extractor or a squashed output cannot be exported")
        return _stack(policy.mlp_extractor.policy_net, where) + _stack(policy.action_net, where), False
    raise ValueError(f"{where}: a {type(policy).__name__} cannot be exported (TRPO, PPO and SAC policies can)")


def _sha256(path: Path) -> str:
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


def _results(model_zip: Path) -> dict:
    """The training run's last episode per weather, as episodes.csv recorded it."""
    from parallel_eplus.runs.policy_files import run_dir_of

    path = run_dir_of(model_zip) / "episodes.csv"
    if not path.is_file():
        return {}
    import pandas as pd

    df = pd.read_csv(path)
    if df.empty or "weather" not in df:
        return {}
    keep = [c for c in df.columns if c in ("power_kw", "reward", "steps") or c.endswith("_pct")]
    last = df.groupby("weather").tail(1).set_index("weather")[keep]
    return {"episodes": int(len(df)), "last_episode_per_weather": json.loads(last.to_json(orient="index"))}


def build(model_zip: Path) -> tuple[PolicyArrays, dict]:
    """The graph's arrays and the contract of a saved policy (refused when it cannot act alone)."""
    from parallel_eplus.runs.norm_stats import read_stats
    from parallel_eplus.runs.policy_files import policy_features, require_policy_files, saved_shapes
    from parallel_eplus.runs.safe_load import load_policy_network

    stats_file = require_policy_files(model_zip)
    saved = run_settings(model_zip)
    _refuse_unexportable(model_zip, saved)
    building_name = saved_building(saved)
    building = load_building(building_name)
    if building.spec.forecasts:
        raise ValueError(
            f"{model_zip}: building {building.spec.name} observes weather forecasts (its spec's forecast entries); "
            "the contract does not describe forecast inputs yet, so it cannot be exported"
        )
    with_time, with_schedule = policy_features(model_zip, building_name)
    n_obs, n_act = saved_shapes(model_zip)
    if n_act != len(building.actions):
        raise ValueError(
            f"{model_zip} acts on {n_act} values; building {building.spec.name} has {len(building.actions)}"
        )
    policy = load_policy_network(model_zip)
    layers, squash = policy_layers(policy, str(model_zip))
    stats = read_stats(stats_file)
    features = (TIME_FEATURES if with_time else ()) + (SCHEDULE_FEATURES if with_schedule else ())
    low, high = building.bounds()
    obs_low = np.array(low + [-1.0] * len(features), np.float32).astype(np.float64)  # the env's float32 bounds
    obs_high = np.array(high + [1.0] * len(features), np.float32).astype(np.float64)
    arrays = PolicyArrays(
        obs_low, obs_high,
        stats.obs_mean if stats.norm_obs else None,
        np.sqrt(stats.obs_var + stats.epsilon) if stats.norm_obs else None,
        float(stats.clip_obs), layers, squash,
        np.array([a.low for a in building.actions], float), np.array([a.high for a in building.actions], float),
        thermostat_pairs(tuple(building.actions)),
    )  # fmt: skip
    if len(obs_low) != n_obs:
        raise ValueError(f"{model_zip} observes {n_obs} values; its building and features make {len(obs_low)}")
    spec = building.spec
    inputs = sensor_entries(building)
    inputs += [
        {"name": f, "source": "time" if f in TIME_FEATURES else "schedule", "unit": "", "low": -1.0, "high": 1.0}
        for f in features
    ]
    outputs = output_entries(building)
    algorithm = saved.get("algorithm", "sac" if squash else "trpo")
    contract = {
        "format": FORMAT,
        "onnx": {"file": ONNX_FILE, "input": INPUT, "input_dtype": "float32", "output": OUTPUT,
                 "output_dtype": "float64", "opset": OPSET},
        "inputs": inputs,
        "time": {
            "required": bool(features),
            "meaning": "the building's local date and time at the start of the step the setpoints are for",
        },
        "outputs": outputs,
        "control_step_s": 86400 // building.steps_per_day,
        "building": {"name": spec.name, "spec": spec.path.name, "sha256": _sha256(spec.path)},
        "policy": {
            "algorithm": algorithm, "model": model_zip.name, "sha256": _sha256(model_zip),
            "statistics": stats_file.name, "run": saved.get("run_name", model_zip.parent.name),
            "seed": saved.get("seed"), "weathers": saved.get("weathers"), "timesteps": saved.get("timesteps"),
            "deterministic": True,
        },
        "results": _results(model_zip),
        "exported": dt.datetime.now(dt.UTC).isoformat(timespec="seconds"),
    }  # fmt: skip
    if with_schedule:
        contract["schedule"] = [list(p) for p in it_load_schedule(spec.idf)]
    return arrays, contract


def reference_actions(model_zip: Path, observations: np.ndarray) -> np.ndarray:
    """Physical setpoints as `evaluate --policy` computes them in process, one observation at a time."""
    from parallel_eplus.runs.policy_files import load_policy

    act = load_policy(model_zip)
    saved = run_settings(model_zip)
    actions = load_building(saved_building(saved)).actions
    low, high, names = [a.low for a in actions], [a.high for a in actions], tuple(a.name for a in actions)
    pairs = thermostat_pairs(tuple(actions))
    return np.array([uncrossed(scale_action(act(o[None, :])[0], low, high, names), pairs) for o in observations])


def sample_observations(arrays: PolicyArrays, n: int = 512, seed: int = 0) -> np.ndarray:
    """Observations around the training statistics (and the bounds' corners), within the bounds."""
    rng = np.random.default_rng(seed)
    lo, hi = arrays.obs_low, arrays.obs_high
    if arrays.obs_mean is not None:
        x = arrays.obs_mean + 3 * arrays.obs_std * rng.standard_normal((n, len(lo)))
    else:
        x = lo + (hi - lo) * rng.random((n, len(lo)))
    return np.clip(np.vstack([x, lo, hi]), lo, hi).astype(np.float32)


def onnx_actions(path: Path, observations: np.ndarray) -> np.ndarray:
    import onnxruntime as ort

    session = ort.InferenceSession(str(path), providers=["CPUExecutionProvider"])
    return session.run([OUTPUT], {INPUT: observations.astype(np.float32)})[0]


def export(run_or_model: Path, out_dir: Path, **planner_options) -> Path:
    """Write controller.onnx and controller.json into `out_dir`; returns the contract's path. A model-based run (or
    its planner) is exported as its planner (planner_export.py, `planner_options` its settings; `progress=False`:
    no progress bar)."""
    import onnx

    from parallel_eplus.deploy.export.planner import export_planner
    from parallel_eplus.learning.model_based.control.saved_planner import planner_source

    planner = planner_source(run_or_model)
    if planner is not None:
        return export_planner(planner, out_dir, **planner_options)
    planner_options.pop("progress", None)  # a policy's export runs no simulation
    if planner_options.get("options"):
        raise ValueError(f"--planner-options: {run_or_model} is a policy, not a planner (a model-based run's)")
    model_zip = model_file(run_or_model)
    arrays, contract = build(model_zip)
    model = build_model(arrays, doc=f"parallel-eplus controller from {model_zip}")
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    onnx_path = out_dir / ONNX_FILE
    with io.atomic_path(onnx_path) as tmp:
        onnx.save(model, str(tmp))
    obs = sample_observations(arrays)
    diff = float(np.max(np.abs(onnx_actions(onnx_path, obs) - reference_actions(model_zip, obs))))
    if not diff <= PARITY_TOLERANCE:
        onnx_path.unlink()
        raise ValueError(f"{model_zip}: the exported graph's setpoints differ from the policy's by {diff:g} (> 1e-5)")
    contract["onnx"]["sha256"] = _sha256(onnx_path)
    contract["export_check"] = {"observations": len(obs), "max_abs_diff": diff, "tolerance": PARITY_TOLERANCE}
    path = out_dir / CONTRACT_FILE
    io.write_text(path, json.dumps(contract, indent=2) + "\n")
    log.info("exported %s -> %s (%d inputs, %d outputs; max difference %.2g)", model_zip, out_dir,
             len(contract["inputs"]), len(contract["outputs"]), diff)  # fmt: skip
    return path
