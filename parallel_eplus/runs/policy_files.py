"""A saved policy on disk: the model, its observation statistics, checkpoints, and loading them to act."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import torch as th
from stable_baselines3.common.vec_env import VecNormalize

from parallel_eplus.buildings.datacenter import observation_names
from parallel_eplus.runs.norm_stats import read_stats
from parallel_eplus.runs.run_files import MODEL_FILE, saves_newest_first

__all__ = ["MODEL_FILE", "saves_newest_first"]  # and the rest; these two live in run_files.py (no torch there)
NORMALIZE_FILE = "vecnormalize.npz"  # data only (norm_stats.py)
LEGACY_SUFFIX = ".pkl"  # SB3's pickled VecNormalize, as saved before 0.3: still read, with a warning


def _latest_checkpoint(path: Path) -> Path:
    """A checkpoint .zip, or the newest save in a run directory: the last checkpoint, or the final model
    when the run finished after it (SB3 ends on a whole batch, past the last checkpoint)."""
    if path.is_file():
        return path
    saves = saves_newest_first(path)
    if not saves:
        raise FileNotFoundError(f"no checkpoint or {MODEL_FILE} in {path}")
    return saves[0]


def stats_target(model_zip: Path) -> Path:
    """Where the data-only statistics of a model or checkpoint are written."""
    if model_zip.name == MODEL_FILE:
        return model_zip.with_name(NORMALIZE_FILE)
    steps = model_zip.stem.split("_")[1]
    return model_zip.with_name(f"model_vecnormalize_{steps}_steps.npz")


def normalization_file(model_zip: Path) -> Path:
    """The statistics saved beside a model or checkpoint: the .npz, else a legacy .pkl if only that exists."""
    target = stats_target(model_zip)
    legacy = target.with_suffix(LEGACY_SUFFIX)
    return legacy if not target.is_file() and legacy.is_file() else target


def replay_buffer_file(model_zip: Path) -> Path:
    """SAC's replay buffer beside a final model or an interrupt checkpoint (periodic checkpoints leave it out:
    up to ~80 MB each; a run resumed from one starts with an empty buffer)."""
    return model_zip.with_name(f"{model_zip.stem}_replay_buffer.pkl")


def run_dir_of(checkpoint: Path) -> Path:
    """The run a saved policy belongs to: the folder holding its config.json, the checkpoint's own or the one above
    (checkpoints/, best/ and cloned/ sit inside their run)."""
    for folder in (checkpoint.parent, checkpoint.parent.parent):
        if (folder / "config.json").is_file():
            return folder
    return checkpoint.parent.parent if checkpoint.parent.name == "checkpoints" else checkpoint.parent


def _saved_policy(model_zip: Path):
    """The policy network of a saved model, whichever algorithm trained it (SAC's includes its critics), built
    without unpickling anything from the file (safe_load.py): a shared policy cannot run code."""
    from parallel_eplus.runs.safe_load import load_policy_network

    return load_policy_network(model_zip)


def saved_shapes(model_zip: Path) -> tuple[int, int]:
    """(observations, actions) of a saved model, read from its JSON metadata without unpickling anything."""
    import json
    import zipfile

    try:
        with zipfile.ZipFile(model_zip) as z:
            data = json.loads(z.read("data"))
        return int(data["observation_space"]["_shape"][0]), int(data["action_space"]["_shape"][0])
    except (zipfile.BadZipFile, KeyError, ValueError, TypeError, IndexError) as e:
        raise ValueError(f"{model_zip}: not a saved policy ({type(e).__name__}: {e})") from None


def require_policy_files(model_zip: Path, context: str = "") -> Path:
    """A saved policy is two files that belong together: the model and its observation statistics; returns
    the latter. Statistics copied from another run (another observation count) are refused."""
    if not model_zip.is_file():
        raise FileNotFoundError(f"{context}policy not found: {model_zip}")
    stats = normalization_file(model_zip)
    if not stats.is_file():
        raise FileNotFoundError(f"{context}observation statistics missing beside the policy: {stats}")
    n_obs, _ = saved_shapes(model_zip)
    n_stats = read_stats(stats).n_observations
    if n_stats != n_obs:
        raise ValueError(
            f"{context}{stats} holds statistics of {n_stats} observations but {model_zip.name} observes {n_obs}: "
            "they come from different runs (keep each model.zip with its own statistics)"
        )
    return stats


def check_actions(model_zip: Path, expected: int, what: str) -> None:
    """Refuse a policy whose action count is not what the simulation it would drive takes."""
    _, n_act = saved_shapes(model_zip)
    if n_act != expected:
        raise ValueError(
            f"{model_zip} acts on {n_act} values but {what} takes {expected}: a policy for another model or building"
        )


def _check_init_from(model_zip: Path, features: tuple[bool, bool]) -> None:
    require_policy_files(model_zip, "--init-from: ")
    saved = policy_features(model_zip)
    old, new = observation_names(*saved), observation_names(*features)
    if new[: len(old)] != old:
        flags = [f for f, on in zip(("--time-features", "--schedule-features"), saved, strict=True) if on]
        trained = f"with {' and '.join(flags)}" if flags else "without --time-features or --schedule-features"
        raise ValueError(
            f"--init-from {model_zip}: that policy was trained {trained}; pass the same flags (more may be added)"
        )


def _warm_start(model_zip: Path, model, env: VecNormalize) -> None:
    """The saved policy's weights and observation statistics, into a run that may observe more.

    Observations added after the saved policy's own (`--schedule-features` on a policy trained with
    `--time-features`, say) enter its first layers with zero weights, so the run starts from exactly
    the saved policy's behaviour; their statistics start at mean 0, variance 1 and keep updating.
    """
    state = model.policy.state_dict()
    for key, value in _saved_policy(model_zip).state_dict().items():
        target = state.get(key)
        if target is not None and value.ndim == target.ndim == 2 and target.shape[1] > value.shape[1]:
            # An input layer over more observations (a wrong row count still fails in load_state_dict).
            value = th.cat([value, th.zeros(value.shape[0], target.shape[1] - value.shape[1])], dim=1)
        state[key] = value
    try:
        model.policy.load_state_dict(state)
    except RuntimeError as e:  # another network shape
        raise ValueError(f"--init-from {model_zip}: its network does not fit this run's: {e}") from e
    stats = read_stats(normalization_file(model_zip))
    n = stats.n_observations
    env.obs_rms.mean[:n], env.obs_rms.var[:n], env.obs_rms.count = stats.obs_mean, stats.obs_var, stats.obs_count


def policy_forecast(model_zip: str | Path) -> tuple[int, str | None]:
    """(forecast hours, forecast error level) a saved policy observes with (`train --forecast`), from its run's
    config.json; (0, None) without one."""
    import json

    config = run_dir_of(Path(model_zip)) / "config.json"
    saved = json.loads(config.read_text()) if config.is_file() else {}
    return int(saved.get("forecast_hours", 0)), saved.get("forecast_error")


def policy_features(model_zip: str | Path, building: str | None = None) -> tuple[bool, bool]:
    """Whether a saved policy observes (`model.TIME_FEATURES`, `model.SCHEDULE_FEATURES`), read from
    the size of its observation statistics beside the sensors of its building (None: the data center), its
    spec's forecasts and its run's `--forecast` hours (`policy_forecast`)."""
    from parallel_eplus.buildings.building import load_building
    from parallel_eplus.buildings.datacenter import SCHEDULE_FEATURES, TIME_FEATURES

    n = read_stats(normalization_file(Path(model_zip))).n_observations
    spec = load_building(building).spec
    sensors = len(load_building(building).observed) + sum(f.count for f in spec.forecasts)
    sensors += policy_forecast(model_zip)[0]
    options = [(t, s) for t in (False, True) for s in (False, True)]
    found = [o for o in options if sensors + len(TIME_FEATURES) * o[0] + len(SCHEDULE_FEATURES) * o[1] == n]
    if not found:
        raise ValueError(f"{model_zip}: a policy over {n} observations does not fit this model")
    return found[0]


def load_policy(model_zip: str | Path):
    """A trained policy and its observation normalizer, ready to act deterministically."""
    model_zip = Path(model_zip)
    stats = require_policy_files(model_zip)
    saved = _saved_policy(model_zip)
    from parallel_eplus.runs.numpy_policy import NumpyPolicy, squashed_mean

    norm = read_stats(stats)
    low, high = saved.action_space.low, saved.action_space.high
    fast = NumpyPolicy(saved).mean if NumpyPolicy.supports(saved) else squashed_mean(saved)

    def act(obs: np.ndarray) -> np.ndarray:
        if fast is not None:  # the Gaussian's mean (SAC: squashed), as SB3's deterministic predict, without torch
            return np.clip(fast(norm.normalize_obs(obs)), low, high).astype(np.float32)
        action, _ = saved.predict(norm.normalize_obs(obs), deterministic=True)
        return action

    return act
