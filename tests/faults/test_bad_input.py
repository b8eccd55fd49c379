"""Bad input at every entry point: one line saying what is wrong, exit status 2, nothing started or written.

(An IDF that EnergyPlus rejects is tests/faults/test_energyplus.py's `test_broken_idf_raises_with_the_error_file_tail`:
only EnergyPlus can judge it, so its error carries the tail of eplusout.err.)
"""

from __future__ import annotations

import logging
import subprocess
import sys

import pytest

from parallel_eplus.cli import main

from ..conftest import our_processes

CASES = {
    "unknown-weather": (["train", "--weathers", "CA,XX"], "unknown weather 'XX'"),
    "missing-epw": (["train", "--weathers", "nowhere.epw"], "weather file not found"),
    "not-an-epw": (["simulate", "--weather", "{tmp}/fake.epw"], "is not an EnergyPlus weather file"),
    "not-a-weather-file": (["evaluate", "--baseline", "--weathers", "CA,notes.txt"], "unknown weather 'notes.txt'"),
    "workers-0": (["train", "--workers", "0"], "--workers must be at least 1"),
    "evaluate-workers-0": (["evaluate", "--baseline", "--workers", "0"], "--workers must be at least 1"),
    "batch-not-divisible": (["train", "--workers", "3", "--batch-size", "1000"], "use 999 or 1002"),
    "run-days-0": (["train", "--run-days", "0"], "--run-days must be within 1..365"),
    "run-days-over-a-year": (["evaluate", "--baseline", "--run-days", "366"], "--run-days within 1..365"),
    "simulate-days-0": (["simulate", "--days", "0"], "run_days must be within 1..365, got 0"),
    "reward-nan": (["train", "--reward", "{tmp}/nan.json"], "reward constants must be finite numbers"),
    "reward-not-json": (["simulate", "--reward", "{tmp}/fake.epw"], "not JSON"),
    "reward-unknown": (["evaluate", "--baseline", "--reward", "{tmp}/typo.json"], "unknown reward constant"),
    "policy-missing": (["evaluate", "--policy", "{tmp}/none/model.zip"], "policy not found"),
    "resume-missing": (["train", "--resume", "{tmp}/runs/none"], "no such run directory or checkpoint"),
}


@pytest.mark.parametrize("case", list(CASES))
def test_bad_input_is_one_line_and_starts_nothing(tmp_path, no_leaks, case, monkeypatch, caplog):
    (tmp_path / "fake.epw").write_text("not a weather file\n")
    (tmp_path / "nan.json").write_text('{"power_weight": NaN}')
    (tmp_path / "typo.json").write_text('{"power_wieght": 1e-5}')
    args, expected = CASES[case]
    argv = [a.replace("{tmp}", str(tmp_path)) for a in args] + ["--quiet"]
    before = sorted(p.name for p in tmp_path.iterdir())
    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr(sys, "argv", ["parallel-eplus", *argv])  # the command line reads a few flags from it
    with caplog.at_level(logging.WARNING):
        assert main(argv) == 2
    [record] = caplog.records
    assert record.levelname == "ERROR" and "\n" not in record.getMessage() and expected in record.getMessage()
    assert sorted(p.name for p in tmp_path.iterdir()) == before  # no run, results or episode folder
    assert our_processes() == []


def test_the_error_reaches_stderr_as_one_line(tmp_path):
    cmd = [sys.executable, "-m", "parallel_eplus.cli", "train", "--workers", "0", "--quiet"]
    out = subprocess.run(cmd, cwd=tmp_path, capture_output=True, text=True, timeout=120)
    assert out.returncode == 2
    [line] = out.stderr.strip().splitlines()
    assert "ERROR" in line and "--workers must be at least 1" in line
