"""`parallel-eplus optimize` end to end on the DOE small office (real EnergyPlus, `--quick`'s short periods): it is
interrupted while training, resumed by the same command without redoing a finished stage, and ends with a report
naming every candidate and either an exported controller or the do-no-harm answer."""

from __future__ import annotations

import json
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pandas as pd
import pytest

from parallel_eplus.buildings.resources import model_file

from .conftest import _started_by_us

pytestmark = pytest.mark.slow


def _command(out: Path) -> list[str]:
    model = model_file("RefBldgSmallOfficeNew2004_Chicago.idf")
    return [sys.executable, "-m", "parallel_eplus.cli", "optimize", str(model), "--out", str(out), "--quick",
            "--weathers", "CA", "--held-out", "IL", "--workers", "2", "--budget-minutes", "10", "--quiet"]  # fmt: skip


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
    answered = (out / "status.json").read_text(), report
    third = subprocess.run(_command(out), capture_output=True, text=True, timeout=300)  # answered: nothing to do
    assert third.returncode == 0 and "answered already" in third.stdout + third.stderr, third.stderr[-3000:]
    assert ((out / "status.json").read_text(), (out / "report.md").read_text()) == answered
    if after["choice"]["chosen"] == "own":  # do no harm: nothing written, and the report says so
        assert "**Chosen: own controls.**" in report and not (out / "controller").exists()
    else:  # linked beside the report, so the folder can move
        assert json.loads((out / "controller" / "controller.json").read_text())
        assert "Written: [controller/controller.json](controller/controller.json)" in report, report


def _our_ray() -> list[str]:
    """Ray's processes this test session started that are still alive."""
    out = subprocess.run(["pgrep", "-af", "gcs_server|raylet|ray::"], capture_output=True, text=True).stdout
    return [ln[:120] for ln in out.splitlines() if ln.strip() and _started_by_us(ln.split()[0])]


def test_a_portfolio_on_ray_answers_each_building_reports_a_broken_one_and_stops_on_ctrl_c(tmp_path, no_leaks):
    """`optimize A B C --ray local`: one Ray task per building. A finished building (the committed portfolio's
    restaurant) is answered from its folder, a broken model is a row saying why, and a Ctrl-C while a third building
    prepares stops its stage, ends the Ray it started and leaves the folder for a rerun."""
    out = tmp_path / "portfolio"
    root = Path(__file__).resolve().parents[1]
    shutil.copytree(root / "results" / "optimize" / "full-service-restaurant", out / "full-service-restaurant")
    broken = tmp_path / "broken.idf"
    broken.write_text("Version,25.2;\nNot:AnObject, at all;\n")
    models = [model_file(f"RefBldg{name}New2004_Chicago.idf") for name in ("FullServiceRestaurant", "SmallOffice")]
    cmd = [sys.executable, "-m", "parallel_eplus.cli", "optimize", str(models[0]), str(broken), "--out", str(out),
           "--ray", "local", "--workers", "2", "--quiet"]  # fmt: skip
    done = subprocess.run(cmd, capture_output=True, text=True, timeout=600)
    assert done.returncode == 1, (done.stdout + done.stderr)[-3000:]  # one building could not be finished
    summary = (out / "summary.md").read_text()
    assert "| full-service-restaurant | own controls |" in summary and "| broken | not finished: preparing" in summary
    assert "2 buildings placed" in done.stderr

    proc = subprocess.Popen([*cmd[:5], str(models[1]), *cmd[6:]], stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                            text=True)  # fmt: skip
    lines = []
    for line in proc.stdout:  # the office's first stage under way on a Ray worker
        lines.append(line)
        if "small-office: prepare" in line:
            break
    proc.send_signal(signal.SIGINT)  # at once: the office's preparing takes ~3 s (a 2 s wait once missed it)
    log = "".join(lines) + proc.communicate(timeout=600)[0]
    assert proc.returncode == 130, log[-3000:]
    assert "stopping 1 buildings' stages" in log
    assert _status(out / "small-office").get("stages", {}).get("prepare", {}).get("state") != "done"
    assert not _our_ray()  # the Ray it started, ended


def test_a_portfolio_stopped_between_chunks_tables_what_is_answered_so_far(tmp_path, no_leaks):
    """`studies/portfolio/run.sh`'s way: several buildings one after another, stopped by Ctrl-C while the second one
    prepares. Its summary is still written: the first building answered (the committed restaurant, a rerun that
    changes nothing), the second named as stopped, so the table grows chunk by chunk."""
    out = tmp_path / "portfolio"
    root = Path(__file__).resolve().parents[1]
    shutil.copytree(root / "results" / "optimize" / "full-service-restaurant", out / "full-service-restaurant")
    models = [model_file(f"RefBldg{name}New2004_Chicago.idf") for name in ("FullServiceRestaurant", "SmallOffice")]
    cmd = [sys.executable, "-m", "parallel_eplus.cli", "optimize", *map(str, models), "--out", str(out), "--quiet"]
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    lines = []
    for line in proc.stdout:  # the restaurant answered, the office's first stage under way
        lines.append(line)
        if "small-office: prepare" in line:
            break
    proc.send_signal(signal.SIGINT)
    log = "".join(lines) + proc.communicate(timeout=300)[0]
    assert proc.returncode == 130, log[-3000:]
    summary = (out / "summary.md").read_text()
    assert "| full-service-restaurant | own controls |" in summary, summary
    assert "| small-office | not finished: stopped before its answer (rerun the same command" in summary, summary
    assert "1 of 2 buildings answered" in summary
