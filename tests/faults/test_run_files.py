"""What a run leaves on disk: a taken run name is refused, statistics are data only, writes are atomic."""

from __future__ import annotations

import contextlib
import logging
import os
import pickle
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from parallel_eplus import io
from parallel_eplus.errors import RunExistsError
from parallel_eplus.runs.norm_stats import read_stats
from parallel_eplus.runs.policy_files import load_policy, normalization_file, policy_features
from parallel_eplus.training.train import train

from ..test_train import small_config

REPO = Path(__file__).resolve().parents[2]
COMMITTED = REPO / "results" / "paper" / "models" / "paper-ca"  # data-only statistics since 0.3


@pytest.fixture
def legacy(tmp_path) -> Path:
    """A policy as saved before 0.3: SB3's pickled VecNormalize beside model.zip."""
    import gymnasium as gym
    from stable_baselines3.common.vec_env import DummyVecEnv

    class Shape(gym.Env):
        observation_space = gym.spaces.Box(-np.inf, np.inf, (6,), np.float32)
        action_space = gym.spaces.Box(-1.0, 1.0, (4,), np.float32)

    d = tmp_path / "legacy"
    d.mkdir()
    for name in ("model.zip", "config.json"):
        (d / name).write_bytes((COMMITTED / name).read_bytes())
    read_stats(COMMITTED / "vecnormalize.npz").wrap(DummyVecEnv([Shape]), training=False).save(d / "vecnormalize.pkl")
    return d


OBS = np.array([[12.0, 23.0, 24.0, 120e3, 110e3, 10e3]], dtype=np.float32)


def _tiny(tmp_path: Path, name: str, **overrides):
    return small_config(
        tmp_path, name, **{"weathers": ["CA"], "run_days": 1, "timesteps": 192, "batch_size": 192, **overrides}
    )


@pytest.mark.slow
def test_a_taken_run_name_is_refused_and_overwrite_moves_the_old_run_aside(tmp_path, no_leaks):
    first = train(_tiny(tmp_path, "probe"), progress=False)
    run, tb = first.parent, tmp_path / "tb" / "probe"
    model, episodes = first.read_bytes(), (run / "episodes.csv").read_bytes()
    events = sorted(p.relative_to(tb) for p in tb.rglob("events.out.tfevents.*"))  # the run's and each weather's

    with pytest.raises(RunExistsError, match=r"--resume .*runs/probe.*--overwrite"):
        train(_tiny(tmp_path, "probe", timesteps=96), progress=False)
    assert first.read_bytes() == model and (run / "episodes.csv").read_bytes() == episodes
    assert sorted(p.relative_to(tb) for p in tb.rglob("events.out.tfevents.*")) == events  # nothing written

    second = train(_tiny(tmp_path, "probe"), progress=False, overwrite=True)
    assert second == first
    [old_run] = (tmp_path / "runs").glob("probe.old-*")
    [old_tb] = (tmp_path / "tb").glob("probe.old-*")
    assert (old_run / "model.zip").read_bytes() == model and (old_run / "episodes.csv").read_bytes() == episodes
    assert sorted(p.relative_to(old_tb) for p in old_tb.rglob("events.out.tfevents.*")) == events
    assert not {p.relative_to(tb) for p in tb.rglob("events.out.tfevents.*")} & set(events)  # new curves start alone


@pytest.mark.slow
def test_the_command_line_refuses_a_taken_run_name_in_one_line(tmp_path):
    (tmp_path / "runs" / "taken").mkdir(parents=True)
    (tmp_path / "runs" / "taken" / "config.json").write_text("{}")
    cmd = [
        sys.executable, "-m", "parallel_eplus.cli", "train", "--run-name", "taken", "--workers", "1",
        "--run-days", "1", "--timesteps", "96", "--batch-size", "96", "--quiet",
    ]  # fmt: skip
    out = subprocess.run(cmd, cwd=tmp_path, capture_output=True, text=True, timeout=120)
    assert out.returncode == 2, out.stderr
    [line] = out.stderr.strip().splitlines()
    assert "--resume runs/taken" in line and "--overwrite" in line
    assert sorted(p.name for p in (tmp_path / "runs" / "taken").iterdir()) == ["config.json"]


@pytest.mark.slow
def test_pickled_statistics_still_load_with_a_warning(legacy, caplog):
    stats = normalization_file(legacy / "model.zip")
    assert stats.name == "vecnormalize.pkl"
    with caplog.at_level(logging.WARNING):
        act = load_policy(legacy / "model.zip")
    assert "is a pickle" in caplog.text and "vecnormalize.pkl" in caplog.text
    a = act(OBS)
    assert a.shape == (1, 4) and np.all(np.abs(a) <= 1)
    assert policy_features(legacy / "model.zip") == (False, False)
    # The data-only copy normalizes exactly as SB3's pickled VecNormalize does.
    with open(stats, "rb") as f:
        norm = pickle.load(f)
    np.testing.assert_array_equal(read_stats(stats).normalize_obs(OBS), norm.normalize_obs(OBS))


def test_statistics_round_trip_as_data_only(legacy, tmp_path):
    with open(normalization_file(legacy / "model.zip"), "rb") as f:
        norm = pickle.load(f)
    from parallel_eplus.runs.norm_stats import save_stats

    path = save_stats(norm, tmp_path / "vecnormalize.npz")
    with np.load(path, allow_pickle=False) as data:  # numbers only: no object arrays
        assert data["obs_mean"].shape == (6,) and float(data["obs_count"]) == norm.obs_rms.count
    back = read_stats(path)
    np.testing.assert_array_equal(back.obs_var, norm.obs_rms.var)
    assert (back.clip_obs, back.gamma, back.norm_reward) == (norm.clip_obs, norm.gamma, norm.norm_reward)
    (tmp_path / "bad.npz").write_bytes(path.read_bytes()[:100])
    with pytest.raises(ValueError, match="bad.npz: not readable normalization statistics"):
        read_stats(tmp_path / "bad.npz")


def test_an_atomic_write_that_fails_leaves_the_previous_file_and_no_temporary(tmp_path):
    target = tmp_path / "episodes.csv"
    io.write_text(target, "a\n1\n")
    with pytest.raises(RuntimeError), io.atomic_path(target) as tmp:
        tmp.write_text("a\n1\n2")
        raise RuntimeError("crash mid-write")
    assert target.read_text() == "a\n1\n" and sorted(tmp_path.iterdir()) == [target]
    io.append_text(target, "2\n")
    assert target.read_text() == "a\n1\n2\n"


def test_an_append_cut_short_is_cut_off_by_the_next_and_rows_read_as_pandas_wrote_them(tmp_path):
    import pandas as pd

    target = tmp_path / "episodes.csv"
    rows = [{"timesteps": 96, "weather": "CA, x", "power_kw": 1 / 3, "noise_sigma": None, "ratio": float("nan"),
             "complete": True, "steps": np.int64(96), "in_band_pct": np.float32(99.5)}, {"timesteps": 192}]  # fmt: skip
    first = io.csv_rows(rows[0], header=True)
    assert first == pd.DataFrame([rows[0]]).to_csv(index=False)  # what episodes.csv held before
    io.append_text(target, first)
    with target.open("ab") as f:  # a writer killed mid-row (or a full disk)
        f.write(b"192,CA,0.5")
    io.append_text(target, io.csv_rows(rows[0] | rows[1]))
    back = pd.read_csv(target)
    assert back["timesteps"].tolist() == [96, 192] and back["weather"].tolist() == ["CA, x"] * 2
    assert back["power_kw"][0] == 1 / 3 and back["noise_sigma"].isna().all() and back["complete"].all()
    (tmp_path / "torn.csv").write_bytes(b"no newline at all")
    io.append_text(tmp_path / "torn.csv", "a\n")
    assert (tmp_path / "torn.csv").read_text() == "a\n"


@pytest.mark.parametrize(
    "name, algorithm", [("paper-ca", "trpo"), ("ppo-ca-co-fl-time", "ppo"), ("residual-demand", "trpo")]
)
def test_a_policy_loads_without_unpickling_and_acts_as_sb3s_own_load(name, algorithm):
    from parallel_eplus.learning.algorithms import ALGORITHMS
    from parallel_eplus.runs.policy_files import _saved_policy

    model_zip = COMMITTED.parent / name / "model.zip"
    safe, full = _saved_policy(model_zip), ALGORITHMS[algorithm].load(model_zip, device="cpu").policy
    obs = np.random.default_rng(0).normal(size=(8, safe.observation_space.shape[0])).astype(np.float32)
    np.testing.assert_array_equal(safe.predict(obs, deterministic=True)[0], full.predict(obs, deterministic=True)[0])
    assert safe.action_space == full.action_space and safe.observation_space.shape == full.observation_space.shape


class _Payload:
    """What a hostile model file could carry: unpickling it runs a command."""

    def __init__(self, marker: Path):
        self.marker = marker

    def __reduce__(self):
        import os

        return (os.system, (f"touch {self.marker}",))


def test_opening_a_shared_policy_runs_none_of_its_code(tmp_path):
    import base64
    import json
    import shutil
    import zipfile

    from sb3_contrib import TRPO

    marker = tmp_path / "code-ran"
    hostile = tmp_path / "hostile"
    hostile.mkdir()
    with zipfile.ZipFile(COMMITTED / "model.zip") as src, zipfile.ZipFile(hostile / "model.zip", "w") as dst:
        for item in src.infolist():
            data = src.read(item)
            if item.filename == "data":
                meta = json.loads(data)
                meta["lr_schedule"][":serialized:"] = base64.b64encode(pickle.dumps(_Payload(marker))).decode()
                data = json.dumps(meta).encode()
            dst.writestr(item, data)
    shutil.copy(COMMITTED / "config.json", hostile)
    shutil.copy(COMMITTED / "vecnormalize.npz", hostile)  # the statistics as data

    act = load_policy(hostile / "model.zip")  # what `evaluate --policy` opens
    assert act(OBS).shape == (1, 4)
    assert not marker.exists(), "loading the policy ran code from the file"
    with contextlib.suppress(Exception):  # the same file through SB3's own load does run it: the test has teeth
        TRPO.load(hostile / "model.zip", device="cpu")
    assert marker.exists()


def test_temporaries_of_a_killed_writer_are_removed_and_a_live_ones_kept(tmp_path):
    dead_pid = subprocess.Popen(["true"])  # a PID that has exited
    dead_pid.wait()
    stale, live = tmp_path / f".model.zip.tmp-{dead_pid.pid}", tmp_path / f".model.zip.tmp-{os.getpid()}"
    stale.write_bytes(b"half")
    live.write_bytes(b"being written")
    assert io.remove_stale_temporaries(tmp_path) == [stale]
    assert live.exists() and not stale.exists()
