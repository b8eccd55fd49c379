"""Observation (and return) normalization statistics as plain data: numbers in an .npz, never a pickle.

A policy is meant to be shared, and opening SB3's `vecnormalize.pkl` unpickles it, which can run any
code its author put there. `vecnormalize.npz` holds only arrays (read with `allow_pickle=False`): the
running means, variances and counts, and VecNormalize's settings. Old `.pkl` files are still read,
with a warning that says so.
"""

from __future__ import annotations

import logging
import zipfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from stable_baselines3.common.running_mean_std import RunningMeanStd
from stable_baselines3.common.vec_env import VecEnv, VecNormalize

from parallel_eplus import io

log = logging.getLogger(__name__)

FORMAT = 1  # bumped if the fields change


@dataclass
class NormStats:
    """What VecNormalize needs to normalize as it did when it was saved."""

    obs_mean: np.ndarray
    obs_var: np.ndarray
    obs_count: float
    ret_mean: float = 0.0
    ret_var: float = 1.0
    ret_count: float = 1e-4
    clip_obs: float = 10.0
    clip_reward: float = 10.0
    gamma: float = 0.99
    epsilon: float = 1e-8
    norm_obs: bool = True
    norm_reward: bool = False

    @property
    def n_observations(self) -> int:
        return len(self.obs_mean)

    @classmethod
    def of(cls, norm: VecNormalize) -> NormStats:
        return cls(
            np.asarray(norm.obs_rms.mean, float), np.asarray(norm.obs_rms.var, float), float(norm.obs_rms.count),
            float(norm.ret_rms.mean), float(norm.ret_rms.var), float(norm.ret_rms.count), float(norm.clip_obs),
            float(norm.clip_reward), float(norm.gamma), float(norm.epsilon), bool(norm.norm_obs),
            bool(norm.norm_reward),
        )  # fmt: skip

    def normalize_obs(self, obs: np.ndarray) -> np.ndarray:
        """VecNormalize.normalize_obs, without a VecNormalize."""
        if not self.norm_obs:
            return obs
        z = (obs - self.obs_mean) / np.sqrt(self.obs_var + self.epsilon)
        return np.clip(z, -self.clip_obs, self.clip_obs).astype(np.float32)

    def wrap(self, venv: VecEnv, training: bool = True) -> VecNormalize:
        """A VecNormalize over `venv` that continues from these statistics."""
        norm = VecNormalize(
            venv, training=training, norm_obs=self.norm_obs, norm_reward=self.norm_reward, clip_obs=self.clip_obs,
            clip_reward=self.clip_reward, gamma=self.gamma, epsilon=self.epsilon,
        )  # fmt: skip
        if norm.obs_rms.mean.shape != self.obs_mean.shape:
            raise ValueError(
                f"observation statistics over {self.n_observations} observations do not fit an env with "
                f"{norm.obs_rms.mean.shape[0]}"
            )
        self.fill(norm.obs_rms, norm.ret_rms)
        return norm

    def fill(self, obs_rms: RunningMeanStd, ret_rms: RunningMeanStd | None = None) -> None:
        obs_rms.mean, obs_rms.var, obs_rms.count = self.obs_mean.copy(), self.obs_var.copy(), self.obs_count
        if ret_rms is not None:
            ret_rms.mean, ret_rms.var = np.float64(self.ret_mean), np.float64(self.ret_var)
            ret_rms.count = self.ret_count

    def save(self, path: Path) -> Path:
        """Written atomically: a crash mid-write leaves the previous file."""
        arrays = {k: np.asarray(v) for k, v in vars(self).items()}
        with io.atomic_path(path) as tmp, open(tmp, "wb") as f:
            np.savez(f, format=np.asarray(FORMAT), **arrays)
        return path


def save_stats(norm: VecNormalize, path: Path) -> Path:
    return NormStats.of(norm).save(path)


def read_stats(path: Path) -> NormStats:
    """Statistics from an .npz (data only), or from a legacy SB3 .pkl with a warning."""
    path = Path(path)
    if path.suffix == ".pkl":
        return _read_pickle(path)
    try:
        with np.load(path, allow_pickle=False) as data:
            if int(data["format"]) > FORMAT:
                raise ValueError(f"{path}: written by a newer parallel-eplus (format {int(data['format'])})")
            fields = {k: data[k] for k in NormStats.__dataclass_fields__ if k in data}
    except (OSError, ValueError, KeyError, EOFError, zipfile.BadZipFile) as e:
        if isinstance(e, FileNotFoundError):
            raise
        raise ValueError(f"{path}: not readable normalization statistics ({e})") from e
    scalars = {k: v.item() for k, v in fields.items() if v.ndim == 0}
    return NormStats(**{**fields, **scalars})


def _read_pickle(path: Path) -> NormStats:
    import pickle

    log.warning(
        "%s is a pickle (SB3's VecNormalize): loading it can run code, so open only your own or trusted files. "
        "Saved again by parallel-eplus it becomes %s (data only).", path, path.with_suffix(".npz").name,
    )  # fmt: skip
    with open(path, "rb") as f:
        try:
            norm = pickle.load(f)
        except Exception as e:  # a damaged pickle raises almost anything
            raise ValueError(f"{path}: not readable normalization statistics ({type(e).__name__}: {e})") from e
    if not isinstance(norm, VecNormalize):
        raise ValueError(f"{path}: holds a {type(norm).__name__}, not VecNormalize statistics")
    return NormStats.of(norm)
