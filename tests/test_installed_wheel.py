"""The release as a user installs it: `python -m build` makes the sdist and the wheel (from the sdist), and the wheel,
installed with its extras into a fresh venv outside the checkout, runs the user's path from another directory:
`simulate` (built-in files travel as package data; nothing is written where the user stands), `building check`, a
1-day `train`, `evaluate --baseline`, `export` and `serve`.

The venv gets torch first, pinned, as scripts/setup.sh does (so pip never pulls CUDA), then the wheel with
`[train,export,serve]`: `train` runs EnergyPlus, learns and evaluates; `export` adds onnx (it includes `train`);
`serve` adds FastAPI and uvicorn. pip's own cache is used as a user's would be; nothing comes from this checkout's
venv. The C bridge compiles from the wheel's copy of its source into a cache folder of the test's own.
"""

from __future__ import annotations

import json
import logging
import os
import shutil
import socket
import subprocess
import sys
import time
import tomllib
import urllib.request
import zipfile
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PROJECT = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
VERSION = PROJECT["version"]
TORCH = next(r for r in PROJECT["optional-dependencies"]["train"] if r.startswith("torch=="))
log = logging.getLogger(__name__)
READINGS = {  # a plausible reading of each of the data center's sensors
    "outdoor_temp_c": 12.5, "west_temp_c": 23.1, "east_temp_c": 23.4,
    "power_w": 95000.0, "it_power_w": 70000.0, "hvac_power_w": 25000.0,
}  # fmt: skip


def _sources(dest: Path) -> Path:
    """The files a release is built from (tracked, plus this branch's package files not committed yet)."""
    files = subprocess.run(["git", "ls-files"], cwd=ROOT, capture_output=True, text=True, check=True).stdout.split()
    wanted = [n for n in files if n.startswith(("parallel_eplus/", "idf/")) or n in ("pyproject.toml", "README.md")]
    wanted += [str(p.relative_to(ROOT)) for p in (ROOT / "parallel_eplus").rglob("*") if p.is_file()]
    for name in wanted:
        if "__pycache__" in name or not (ROOT / name).is_file():
            continue
        (dest / name).parent.mkdir(parents=True, exist_ok=True)
        shutil.copy2(ROOT / name, dest / name)
    return dest


def _run(cmd: list, cwd: Path, env: dict, timeout: float) -> subprocess.CompletedProcess:
    """Run a command to success; its duration is logged (pytest shows it with the failure, or with `-o log_cli=1`)."""
    start = time.monotonic()
    done = subprocess.run([str(c) for c in cmd], cwd=cwd, env=env, capture_output=True, text=True, timeout=timeout)
    log.info("%.1f s: %s", time.monotonic() - start, " ".join(str(c) for c in cmd[:4]))
    assert done.returncode == 0, f"{cmd}: exit {done.returncode}\n{done.stdout[-2000:]}\n{done.stderr[-3000:]}"
    return done


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _get(url: str, body: dict | None = None) -> dict:
    data = None if body is None else json.dumps(body).encode()
    request = urllib.request.Request(url, data=data, headers={"Content-Type": "application/json"})
    with urllib.request.urlopen(request, timeout=10) as r:
        return json.loads(r.read())


def _serve(pe: Path, controller: Path, cwd: Path, env: dict, log: Path) -> tuple[dict, dict, dict]:
    """Start `parallel-eplus serve`, ask /health and one POST /act, stop it: (health, the answer, the contract)."""
    contract = json.loads((controller / "controller.json").read_text())
    sensors = {i["name"]: READINGS[i["name"]] for i in contract["inputs"] if i["source"] == "sensor"}
    port = _free_port()
    url = f"http://127.0.0.1:{port}"
    with log.open("w") as out:
        server = subprocess.Popen([pe, "serve", controller, "--port", str(port)], cwd=cwd, env=env, stdout=out,
                                  stderr=subprocess.STDOUT)  # fmt: skip
    try:
        deadline = time.monotonic() + 60
        while True:
            try:
                _get(url + "/health")
                break
            except OSError:
                if server.poll() is not None or time.monotonic() > deadline:
                    raise AssertionError(f"the server did not start: {log.read_text()}") from None
                time.sleep(0.2)
        answer = _get(url + "/act", {"time": "2013-07-02T14:15:00", "sensors": sensors})
        health = _get(url + "/health")
    finally:
        server.terminate()
        server.wait(timeout=30)
    return health, answer, contract


@pytest.mark.slow
def test_the_wheel_installed_outside_the_checkout_trains_evaluates_exports_and_serves(tmp_path, no_leaks):
    # The sdist and the wheel, as a release builds them (the wheel from the sdist, in an isolated build env).
    src, dist = _sources(tmp_path / "src"), tmp_path / "dist"
    _run([sys.executable, "-m", "build", "--outdir", dist, src], tmp_path, dict(os.environ), 600)
    (wheel,) = dist.glob(f"parallel_eplus-{VERSION}-py3-none-any.whl")
    assert list(dist.glob(f"parallel_eplus-{VERSION}.tar.gz"))
    names = set(zipfile.ZipFile(wheel).namelist())
    models = ("2ZoneDataCenterHVAC_wEconomizer.idf", "2ZoneDataCenterHVAC_wEconomizer_agent.idf")
    shipped = ["buildings/specs/datacenter-2zone.toml", "engine/eplus_side/eplus_callback.c"]
    shipped += [f"buildings/models/{m}" for m in models]
    for name in shipped:
        assert f"parallel_eplus/{name}" in names, name
    assert not any(n.endswith(".epw") for n in names)  # the EnergyPlus wheel ships the paper's weathers

    # A fresh venv outside the checkout: torch pinned first (the CPU build), then the wheel with its extras.
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "VIRTUAL_ENV")}
    venv = tmp_path / "venv"
    _run([sys.executable, "-m", "venv", venv], tmp_path, env, 300)
    # --no-compile: no .pyc written at install (torch alone has thousands of files); imports compile what they use
    pip = [venv / "bin" / "python", "-m", "pip", "install", "-q", "--disable-pip-version-check", "--no-compile"]
    _run([*pip, TORCH], tmp_path, env, 900)
    _run([*pip, f"{wheel}[train,export,serve]"], tmp_path, env, 900)

    user = tmp_path / "user"  # where the user stands: a directory of their own
    user.mkdir()
    cache = tmp_path / "cache"  # the C bridge compiled from the wheel's source, not found in the developer's cache
    env_user = env | {"XDG_CACHE_HOME": str(cache)}
    pe = venv / "bin" / "parallel-eplus"
    probe = "import parallel_eplus.buildings.datacenter as m; print(m.__file__); print(m.AGENT_IDF)"
    where = _run([venv / "bin" / "python", "-c", probe], user, env_user, 120).stdout.split()
    assert len(where) == 2 and all(w.startswith(str(venv)) for w in where), where  # the model is the wheel's
    assert _run([pe, "--version"], user, env_user, 60).stdout.strip() == f"parallel-eplus {VERSION}"
    simulate = _run([pe, "simulate", "--days", "1", "--quiet", "--weather", "CA"], user, env_user, 600)
    assert "samples in band" in simulate.stdout
    assert list(user.iterdir()) == []  # nothing written where the user stands

    check = _run([pe, "building", "check", "datacenter-2zone"], user, env_user, 300)
    assert "datacenter-2zone: ok" in check.stdout + check.stderr
    _run([pe, "train", "--workers", "1", "--weathers", "CA", "--run-days", "1", "--timesteps", "96",
          "--batch-size", "96", "--run-name", "wheel"], user, env_user, 600)  # fmt: skip
    assert (user / "runs" / "wheel" / "model.zip").is_file()
    if shutil.which("cc"):
        assert list((cache / "parallel-eplus").glob("eplus_callback-*.so")), "the C bridge did not compile"
    _run([pe, "evaluate", "--baseline", "--policy", "runs/wheel/model.zip", "--weathers", "CA", "--run-days", "1",
          "--workers", "1", "--out", "results"], user, env_user, 600)  # fmt: skip
    table = (user / "results" / "results.md").read_text()
    assert "**Baseline**" in table and "**TRPO (CA)**" in table, table
    _run([pe, "export", "runs/wheel", "-o", "controller"], user, env_user, 300)

    health, answer, contract = _serve(pe, user / "controller", user, env_user, tmp_path / "serve.log")
    assert (health["act"], health["refused"]) == (1, 0)
    outputs = {o["name"]: o for o in contract["outputs"]}
    assert set(answer["setpoints"]) == set(outputs)
    for name, setpoint in answer["setpoints"].items():
        assert outputs[name]["low"] <= setpoint["value"] <= outputs[name]["high"], (name, setpoint)
    assert sorted(p.name for p in user.iterdir()) == ["controller", "results", "runs", "tensorboard_logs"]
    shutil.rmtree(venv)  # ~1.5 GB; pytest keeps a failed test's for a look
