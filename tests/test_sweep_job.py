"""A sweep as a Ray job (`ray job submit`), stopped with `ray job stop`: checkpoints kept, nothing left running.

A one-node Ray of the test's own (`ray start --head --block`, token authentication, its own ports and temp
folder), so it runs in CI; docs/cluster.md shows the same on the two-node cluster.
"""

from __future__ import annotations

import json
import os
import secrets
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import pytest

from .conftest import our_pipe_dirs, our_processes

RAY = str(Path(sys.executable).parent / "ray")


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _listening(port: int) -> bool:
    with socket.socket() as s:
        return s.connect_ex(("127.0.0.1", port)) == 0


@pytest.fixture
def ray_head():
    """A head node with the job server (the dashboard) on 127.0.0.1; yields (jobs address, environment)."""
    pytest.importorskip("ray")
    state = Path(tempfile.mkdtemp(prefix="pe-ray-", dir="/tmp"))  # short: Ray's socket paths have a length limit
    token = state / "token"
    token.write_text(secrets.token_hex(32))
    token.chmod(0o600)
    env = {**os.environ, "RAY_AUTH_MODE": "token", "RAY_AUTH_TOKEN_PATH": str(token), "RAY_USAGE_STATS_ENABLED": "0"}
    env.pop("RAY_ADDRESS", None)
    dashboard = free_port()
    cmd = [RAY, "start", "--head", "--block", "--port", str(free_port()), "--node-ip-address", "127.0.0.1",
           "--num-cpus", "2", "--include-dashboard=true", "--dashboard-host", "127.0.0.1", "--dashboard-port",
           str(dashboard), "--dashboard-agent-listen-port", str(free_port()), "--ray-client-server-port",
           str(free_port()), "--temp-dir", str(state / "ray"), "--disable-usage-stats"]  # fmt: skip
    head = subprocess.Popen(cmd, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)
    address = f"http://127.0.0.1:{dashboard}"
    try:
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline:  # the job server answers once the head's agent is up
            assert head.poll() is None, "ray start --head exited"
            if not _listening(dashboard):  # (a socket's answer costs nothing; each `ray job list` is a Python start)
                time.sleep(0.25)
                continue
            ok = subprocess.run([RAY, "job", "list", "--address", address], env=env, capture_output=True)
            if ok.returncode == 0:
                break
            time.sleep(1)
        yield address, env
    finally:
        head.send_signal(signal.SIGTERM)  # `ray start --block` stops the node's processes, then itself
        try:
            head.wait(60)
        except subprocess.TimeoutExpired:
            os.killpg(head.pid, signal.SIGKILL)
            head.wait()
        shutil.rmtree(state, ignore_errors=True)


@pytest.mark.slow
def test_a_sweep_submitted_as_a_ray_job_stops_with_checkpoints_and_nothing_left(tmp_path, ray_head):
    address, env = ray_head
    pipes_before = our_pipe_dirs()
    spec = tmp_path / "spec.toml"
    spec.write_text('name = "job"\nseeds = [0, 1]\n[train]\nworkers = 2\nweathers = "CA"\nrun_days = 1\n'
                    "timesteps = 20000\nbatch_size = 192\ncheckpoint_every = 192\n")  # fmt: skip
    job = ["--address", address]
    submit = [RAY, "job", "submit", *job, "--submission-id", "sweep-job", "--no-wait", "--runtime-env-json",
              json.dumps({"env_vars": {"RAY_JOB_STOP_WAIT_TIME_S": "120"}}), "--",
              "bash", "-c", f"cd {tmp_path} && {sys.executable} -m parallel_eplus.cli sweep {spec}"]  # fmt: skip
    out = subprocess.run(submit, env=env, capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stdout + out.stderr
    checkpoints = tmp_path / "runs" / "job" / "seed-0" / "checkpoints"
    deadline = time.monotonic() + 240
    while not list(checkpoints.glob("model_*_steps.zip")) and time.monotonic() < deadline:
        time.sleep(0.5)
    logs = subprocess.run([RAY, "job", "logs", *job, "sweep-job"], env=env, capture_output=True, text=True).stdout
    assert list(checkpoints.glob("model_*_steps.zip")), logs

    stop = subprocess.run([RAY, "job", "stop", *job, "sweep-job"], env=env, capture_output=True, text=True, timeout=180)
    assert stop.returncode == 0, stop.stdout + stop.stderr
    status = subprocess.run([RAY, "job", "status", *job, "sweep-job"], env=env, capture_output=True, text=True)
    assert "was stopped" in status.stdout + status.stderr
    logs = subprocess.run([RAY, "job", "logs", *job, "sweep-job"], env=env, capture_output=True, text=True).stdout
    cut_at = max(int(p.stem.split("_")[1]) for p in checkpoints.glob("model_*_steps.zip"))
    # saved on the stop, at the step the trial stopped (its own log line reaches `ray job logs` only if Ray's log
    # monitor forwards it before the trial's process ends, so the run folder is what tells)
    status = json.loads((checkpoints.parent / "status.json").read_text())
    assert status["state"] == "stopped" and status["steps"] == cut_at, (status, logs)
    assert (checkpoints / f"model_vecnormalize_{cut_at}_steps.npz").is_file()
    assert "sweep job stopped" in logs
    assert our_processes() == [] and our_pipe_dirs() - pipes_before == set()
