"""When EnergyPlus fails: prompt, specific errors with the log tail, and nothing left behind."""

from __future__ import annotations

import os
import signal
import time

import numpy as np
import pytest

from parallel_eplus import EnergyPlusEnv, EnergyPlusError
from parallel_eplus.buildings.datacenter import AGENT_IDF

from ..conftest import our_processes


@pytest.mark.slow
def test_killed_energyplus_raises_promptly_and_leaves_nothing(tmp_path, no_leaks):
    env = EnergyPlusEnv(weather="CA", run_days=2, output_dir=tmp_path)
    try:
        env.reset()
        for _ in range(10):
            env.step(np.zeros(4))
        os.kill(env.sim.proc.pid, signal.SIGKILL)
        t0 = time.monotonic()
        with pytest.raises(EnergyPlusError, match="died") as err:
            for _ in range(5):
                env.step(np.zeros(4))
        assert time.monotonic() - t0 < 5
        assert err.value.episode_dir == tmp_path / "episode-000001-CA"
        assert our_processes() == []
    finally:
        env.close()


@pytest.mark.slow
def test_hung_energyplus_hits_the_timeout(tmp_path, no_leaks):
    env = EnergyPlusEnv(weather="CA", run_days=1, output_dir=tmp_path, step_timeout_s=1.0)
    try:
        env.reset()
        os.kill(env.sim.proc.pid, signal.SIGSTOP)
        t0 = time.monotonic()
        with pytest.raises(EnergyPlusError, match="within 1 s"):
            env.step(np.zeros(4))
        assert time.monotonic() - t0 < 4
    finally:
        env.close()


def test_missing_files_are_reported_before_spawning(tmp_path):
    with pytest.raises(FileNotFoundError, match="weather file not found"):
        EnergyPlusEnv(weather=tmp_path / "nowhere.epw")
    with pytest.raises(ValueError, match="unknown weather"):
        EnergyPlusEnv(weather="XX")
    with pytest.raises(FileNotFoundError, match="model file not found"):
        EnergyPlusEnv(idf=tmp_path / "nowhere.idf")
    with pytest.raises(ValueError, match="unknown model"):
        EnergyPlusEnv(model="fan_only")
    assert not any(tmp_path.iterdir())


def test_broken_idf_raises_with_the_error_file_tail(tmp_path, no_leaks):
    broken = tmp_path / "broken.idf"
    text = AGENT_IDF.read_text(encoding="latin-1")
    broken.write_text(text.replace("EnclosureAveraged,", "NoSuchMethod,"), encoding="latin-1")
    env = EnergyPlusEnv(weather="CA", run_days=1, output_dir=tmp_path / "out", idf=broken)
    try:
        t0 = time.monotonic()
        with pytest.raises(EnergyPlusError) as err:
            env.reset()
        assert time.monotonic() - t0 < 30
        assert "Severe" in str(err.value) or "Fatal" in str(err.value)
        assert "eplusout.err" in err.value.err_tail
    finally:
        env.close()


def test_the_energyplus_side_exits_when_its_env_died_before_it_opened_the_pipes(tmp_path):
    """A learner or Ray actor killed right after starting EnergyPlus holds no pipe end: the child must not wait."""
    import subprocess
    import sys

    from parallel_eplus.engine.pipes.leftovers import CALLBACK_MODULE

    act, obs = tmp_path / "act", tmp_path / "obs"
    os.mkfifo(act)
    os.mkfifo(obs)
    args = ["--act-pipe", act, "--obs-pipe", obs, "--idf", "m.idf", "--epw", "w.epw", "--output-dir", tmp_path,
            "--steps", "96"]  # fmt: skip
    done = subprocess.run([sys.executable, "-m", CALLBACK_MODULE, *map(str, args)], capture_output=True, text=True,
                          timeout=30)  # fmt: skip
    assert done.returncode == 1 and "the env is gone" in done.stderr


def test_a_failed_episode_leaves_the_evaluation_standing(tmp_path, no_leaks, capsys, broken_weather):
    """One weather's EnergyPlus fails: the other episodes finish and are written, the report names the
    failed one with EnergyPlus's own words, and the command exits 1 (a model's own controls can fail on
    one weather: the CRAC's on CO)."""
    import pandas as pd

    from parallel_eplus.cli import main

    out = tmp_path / "eval"
    argv = ["evaluate", "--baseline", "--weathers", f"CA,{broken_weather}", "--run-days", "1"]
    assert main([*argv, "--workers", "2", "--out", str(out), "--quiet"]) == 1
    assert list(pd.read_csv(out / "results.csv")["weather"]) == ["CA"]
    report = (out / "results.md").read_text()
    assert "## Episodes that did not finish" in report
    assert "| Baseline | Broken |" in report and "Invalid Date info in Weather Line" in report
    assert "Invalid Date info in Weather Line" in capsys.readouterr().out


def test_a_failed_episode_stops_a_sweep_that_averages(tmp_path, no_leaks, broken_weather):
    """Without `keep_going` (the algorithm comparison averages over weathers) the failure is raised."""
    from parallel_eplus.evaluation.controllers import BASELINE_LABEL, Controller
    from parallel_eplus.evaluation.sweep import run_sweep

    with pytest.raises(EnergyPlusError, match="Broken"):
        run_sweep([Controller(BASELINE_LABEL, "baseline")], ["CA", str(broken_weather)], 1, 2,
                  tmp_path / "eval", progress=False)  # fmt: skip


def test_an_error_headline_quotes_energyplus_first_severe_line(tmp_path):
    """The cause, not the summary: the first severe line of the error file, else of the tail it carries."""
    (tmp_path / "eplusout.err").write_text(
        "   ** Warning ** something minor\n   ** Severe  ** Temperature (high) out of bounds (201.85]\n"
        "   ** Severe  ** Temperature (high) out of bounds (202.05]\n   **  Fatal  ** too many errors\n"
    )
    assert EnergyPlusError("[CO] failed", tmp_path).headline == (
        "[CO] failed; ** Severe  ** Temperature (high) out of bounds (201.85]"
    )
    assert EnergyPlusError("[CA] failed", None, "   **  Fatal  ** Error in Reading Weather Data").headline == (
        "[CA] failed; **  Fatal  ** Error in Reading Weather Data"
    )
    assert EnergyPlusError("[CA] failed").headline == "[CA] failed"
