"""`parallel-eplus optimize` end to end on the DOE small office (real EnergyPlus, `--quick`'s short periods): it is
interrupted while training, resumed by the same command without redoing a finished stage, and ends with a report
naming every candidate and either an exported controller or the do-no-harm answer."""

from __future__ import annotations

import json
import signal
import subprocess
import sys
import time
from pathlib import Path

import pandas as pd
import pytest

from parallel_eplus.buildings.resources import model_file

pytestmark = pytest.mark.slow


def _command(out: Path) -> list[str]:
    from parallel_eplus.cli.parser import build_parser

    try:  # `parallel-eplus optimize` once parser.py declares it; cli/optimize.py's own parser until then
        build_parser().parse_args(["optimize", "x.idf"])
        entry = ["-m", "parallel_eplus.cli", "optimize"]
    except SystemExit:
        entry = ["-m", "parallel_eplus.cli.optimize"]
    model = model_file("RefBldgSmallOfficeNew2004_Chicago.idf")
    return [sys.executable, *entry, str(model), "--out", str(out), "--quick", "--weathers", "CA", "--held-out", "IL",
            "--workers", "2", "--budget-minutes", "10", "--quiet"]  # fmt: skip


def _status(out: Path) -> dict:
    try:
        return json.loads((out / "status.json").read_text())
    except (OSError, ValueError):
        return {}


def test_optimize_is_interrupted_resumes_and_answers(tmp_path):
    out = tmp_path / "office"
    first = subprocess.Popen(_command(out), stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    deadline = time.time() + 240
    checkpoints = out / "runs" / "learned" / "checkpoints"
    while time.time() < deadline and first.poll() is None:  # under way: training, past its first checkpoint
        if any(checkpoints.glob("*.pt")):
            break
        time.sleep(1)
    assert first.poll() is None, first.communicate()[0][-3000:]
    first.send_signal(signal.SIGINT)
    log = first.communicate(timeout=300)[0]
    assert first.returncode == 130, log[-3000:]
    before = _status(out)["stages"]
    assert before["prepare"]["state"] == before["own"]["state"] == "done"
    assert before["reset"]["state"] == "skipped"  # the small office has no air loop the starter takes over
    assert before.get("train", {}).get("state") != "done"

    again = subprocess.run(_command(out), capture_output=True, text=True, timeout=600)
    assert again.returncode == 0, (again.stdout + again.stderr)[-3000:]
    status = _status(out)
    after = status["stages"]
    for stage in ("prepare", "periods", "own", "reset"):  # finished before the interruption: not redone
        assert after[stage]["finished"] == before[stage]["finished"], stage
    assert status["sessions"] == 2
    assert "--resume" in (out / "logs" / "train.log").read_text()  # training continued from its checkpoint
    assert after["train"]["state"] == "done" and after["train"]["steps"] == 600

    report = (out / "report.md").read_text()
    assert "| own controls | held-out |" in report and "| learned (thermostat-planner) | held-out |" in report
    assert "Guideline 36's supply-air reset: the spec has no supply-air action" in report
    assert (out / "savings.png").is_file() and (out / "typical-day.png").is_file()
    results = pd.read_csv(out / "results" / "quick.csv")
    assert set(results.candidate) == {"own", "learned"} and set(results.weather) == {"CA", "IL"}
    if after["choice"]["chosen"] == "own":  # do no harm: nothing written, and the report says so
        assert "**Chosen: own controls.**" in report and not (out / "controller").exists()
    else:
        assert json.loads((out / "controller" / "controller.json").read_text())
