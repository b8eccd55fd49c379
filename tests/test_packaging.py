"""The package works installed from its wheel, from any directory: built-in files travel as package data
(test_installed_wheel.py: the wheel installed outside the checkout runs `simulate` and the user's path there)."""

from __future__ import annotations

import json
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

from parallel_eplus.buildings import resources
from parallel_eplus.buildings.spec.load import load_spec

ROOT = resources.SOURCE_ROOT
PYPROJECT = tomllib.loads((ROOT / "pyproject.toml").read_text())


def test_every_subpackage_is_listed_for_the_wheel():
    """pyproject.toml lists packages (the idf/ mapping rules out `find`): a new one must be added there."""
    found = {".".join(p.parent.relative_to(ROOT).parts) for p in (ROOT / "parallel_eplus").rglob("__init__.py")}
    listed = set(PYPROJECT["tool"]["setuptools"]["packages"])
    assert found - listed == set(), "add these to [tool.setuptools] packages in pyproject.toml"


def test_builtin_specs_name_files_an_install_has():
    """Every built-in spec's model ships (idf/ is mapped into the wheel, or the EnergyPlus wheel has it); its
    weathers are in the EnergyPlus wheel."""
    energyplus_weather = resources.weather_dirs()[-1]
    assert energyplus_weather.parts[-3:] == ("pyenergyplus", "data", "weather")
    specs = sorted(resources.spec_dir().glob("*.toml"))
    assert specs
    for path in specs:
        spec = load_spec(path)
        # ours (idf/ ships in the wheel), or a prototype the EnergyPlus wheel ships, used as it is
        assert spec.idf.parent in (ROOT / "idf", energyplus_weather.parent / "model"), path
        for weather in spec.weathers.values():
            assert (energyplus_weather / weather.name).is_file(), f"{path.name}: {weather.name} would not install"


def test_spec_paths_relative_absolute_or_builtin(tmp_path):
    builtin = resources.spec_dir() / "datacenter-2zone.toml"
    text = "".join(ln for ln in builtin.read_text().splitlines(True) if not ln.startswith("baseline_idf"))
    idf = resources.model_file("2ZoneDataCenterHVAC_wEconomizer_agent.idf")
    (tmp_path / "models").mkdir()
    shutil.copy(idf, tmp_path / "models" / "mine.idf")
    relative = tmp_path / "relative.toml"
    relative.write_text(text.replace('idf = "2ZoneDataCenterHVAC_wEconomizer_agent.idf"', 'idf = "models/mine.idf"'))
    assert load_spec(relative).idf == tmp_path / "models" / "mine.idf"
    absolute = tmp_path / "absolute.toml"
    absolute.write_text(text.replace('idf = "2ZoneDataCenterHVAC_wEconomizer_agent.idf"', f'idf = "{idf}"'))
    assert load_spec(absolute).idf == idf
    # A bare model name is a built-in model only in a built-in spec; weathers resolve by bare name anywhere.
    copied = tmp_path / "copied.toml"
    copied.write_text(text)
    with pytest.raises(ValueError, match=r'idf: "2ZoneDataCenterHVAC_wEconomizer_agent.idf" not found \(looked in '):
        load_spec(copied)
    # ... and a model of the EnergyPlus wheel, used unmodified, by bare name in any spec (portable between installs)
    office = tmp_path / "office.toml"
    office.write_text((resources.spec_dir() / "office-small.toml").read_text())
    assert load_spec(office).idf == resources.model_file("RefBldgSmallOfficeNew2004_Chicago.idf")
    spec = load_spec(absolute)
    assert spec.weathers["CA"] == resources.weather_file("USA_CA_San.Francisco.Intl.AP.724940_TMY3.epw")
    missing = tmp_path / "missing.toml"
    missing.write_text(absolute.read_text().replace("USA_CA_San", "USA_CA_Sna"))
    with pytest.raises(ValueError, match=r'weathers.CA: "USA_CA_Sna.Francisco.Intl.AP.724940_TMY3.epw" not found'):
        load_spec(missing)


def test_spec_file_by_path_or_builtin_name(tmp_path):
    assert set(resources.builtin_specs()) >= {"datacenter-2zone", "datacenter-crac", "office-small"}
    assert resources.spec_file("datacenter-crac") == resources.spec_dir() / "datacenter-crac.toml"
    mine = tmp_path / "mine.toml"
    mine.write_text("")
    assert resources.spec_file(mine) == mine
    with pytest.raises(
        FileNotFoundError, match=r"'datacenter-crc' not found: give a .toml path or one of .*datacenter-crac"
    ):
        resources.spec_file("datacenter-crc")


@pytest.fixture(scope="module")
def wheel(tmp_path_factory) -> Path:
    """Build from a copy of the tracked sources, as a release would, leaving the checkout untouched."""
    tmp_path = tmp_path_factory.mktemp("wheel")
    src = tmp_path / "src"
    files = subprocess.run(["git", "ls-files"], cwd=ROOT, capture_output=True, text=True, check=True).stdout.split()
    for name in files:
        if name.startswith(("parallel_eplus/", "idf/")) or name in ("pyproject.toml", "README.md", "LICENSE", "NOTICE"):
            (src / name).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(ROOT / name, src / name)
    for path in (ROOT / "parallel_eplus").rglob("*"):  # and this branch's files not committed yet
        if path.is_file() and "__pycache__" not in path.parts:
            (src / path.relative_to(ROOT)).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(path, src / path.relative_to(ROOT))
    out = tmp_path / "dist"
    cmd = [sys.executable, "-m", "pip", "wheel", "--no-deps", "--no-build-isolation", "-q", "-w", out, src]
    subprocess.run(cmd, check=True, capture_output=True)
    (wheel,) = out.glob("parallel_eplus-*.whl")
    return wheel


def test_the_wheel_carries_the_licences(wheel):
    """Apache-2.0 for the package; EnergyPlus's licence beside the models derived from its examples, and in the
    wheel's licence files with the NOTICE that says which files it covers."""
    archive = zipfile.ZipFile(wheel)
    names = archive.namelist()
    energyplus = (ROOT / "idf" / "EnergyPlus-LICENSE.txt").read_text()
    assert archive.read("parallel_eplus/buildings/models/EnergyPlus-LICENSE.txt").decode() == energyplus
    licences = {n.split("/licenses/", 1)[1]: n for n in names if ".dist-info/licenses/" in n}
    assert {"LICENSE", "NOTICE", "idf/EnergyPlus-LICENSE.txt"} <= set(licences), licences
    assert energyplus in archive.read(licences["NOTICE"]).decode()
    assert "Apache License" in archive.read(licences["LICENSE"]).decode()


def test_the_energyplus_side_process_imports_no_data_or_learning_libraries():
    """Every episode starts a fresh EnergyPlus-side process: pandas and pyarrow alone cost it 0.2 s of start-up and
    ~70 MB of its peak memory (a worker's 245 MB against 313 MB), torch or Ray far more."""
    probe = "import sys, parallel_eplus.engine.eplus_side.callback; print(' '.join(sorted(sys.modules)))"
    loaded = set(
        subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, check=True).stdout.split()
    )
    heavy = {"pandas", "pyarrow", "torch", "ray", "stable_baselines3", "sb3_contrib", "matplotlib", "scipy"}
    assert not heavy & loaded, f"the EnergyPlus side imports {sorted(heavy & loaded)}"


def test_a_ray_actor_collecting_on_its_node_imports_neither_torch_nor_sb3(tmp_path):
    """A Ray backend's actor (learning/ray_actor.py) acts on the policy's numpy snapshot: its process, given what the
    learner sends it each batch (the snapshot and the observation statistics), loads neither torch nor SB3 (~3 s of
    CPU and hundreds of MB per actor). Checked in a fresh process: Ray's idle workers may hold anything an earlier
    task imported."""
    import pickle

    import numpy as np
    import torch as th
    from gymnasium import spaces
    from stable_baselines3.common.policies import ActorCriticPolicy

    from parallel_eplus.learning.fragments import BatchOrder, ObsNormalizer
    from parallel_eplus.runs.numpy_policy import NumpyPolicy

    obs, act = spaces.Box(-np.inf, np.inf, (6,)), spaces.Box(-1.0, 1.0, (4,))
    policy = ActorCriticPolicy(obs, act, lambda _: 1e-3, net_arch=[32, 32], activation_fn=th.nn.Tanh)
    order = BatchOrder(NumpyPolicy(policy), ObsNormalizer(np.zeros(6), np.ones(6), 1e-8, 10.0), 64, 0.99,
                       (act.low, act.high))  # fmt: skip
    sent = tmp_path / "order.pkl"
    sent.write_bytes(pickle.dumps(order))
    probe = f"""import pickle, sys
import numpy as np
from parallel_eplus.learning.ray_actor import actor_class
import parallel_eplus.envs.vector_env, parallel_eplus.learning.episode_keys, parallel_eplus.learning.fragments
order = pickle.loads(open({str(sent)!r}, "rb").read())
actions, values, log_probs = order.policy.sample(order.normalizer(np.ones((1, 6))), np.random.default_rng(0))
assert actions.shape == (1, 4)
print(" ".join(sorted(sys.modules)))"""
    loaded = set(
        subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, check=True).stdout.split()
    )
    assert not {"torch", "stable_baselines3"} & loaded, sorted({"torch", "stable_baselines3"} & loaded)


# never in a plant room's install (the `train` extra's)
HEAVY = {"torch", "stable-baselines3", "sb3-contrib", "pyenergyplus-lbnl", "gymnasium", "pandas", "matplotlib"}


def _resolve(requirement: str) -> dict[str, str]:
    """What `pip install REQUIREMENT` would install into an empty environment: name -> version, from PyPI's
    metadata (nothing is downloaded beyond it, nothing installed)."""
    cmd = [sys.executable, "-m", "pip", "install", "--dry-run", "--ignore-installed", "--quiet", "--report", "-"]
    run = subprocess.run([*cmd, requirement], capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, run.stderr[-2000:]
    return {i["metadata"]["name"].lower(): i["metadata"]["version"] for i in json.loads(run.stdout)["install"]}


@pytest.mark.slow
def test_the_serve_extra_installs_a_controller_server_without_the_training_stack(wheel):
    """`pip install parallel-eplus[serve,bacnet]` (`serve --bacnet`): BAC0 on bacpypes3, onnxruntime, never torch, SB3
    or EnergyPlus (issue 41); what [serve] alone installs: the serve-only install's test below. The base dependencies
    are what the server needs; the rest is the `train` extra."""
    supervisor = _resolve(f"{wheel}[serve,bacnet]")  # `serve --bacnet`: BAC0 on bacpypes3, still no training stack
    assert {"bac0", "bacpypes3", "onnxruntime"} <= set(supervisor) and not HEAVY & set(supervisor), sorted(supervisor)
    extras = PYPROJECT["project"]["optional-dependencies"]
    assert any(r.startswith("torch==") for r in extras["train"]) and "parallel-eplus[train]" in extras["export"]


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.mark.slow
def test_a_serve_only_install_serves_a_controller_and_other_commands_name_the_extra(wheel, tmp_path):
    """A fresh venv with only the wheel's [serve] extra (from PyPI): onnxruntime, FastAPI and uvicorn, never torch, SB3
    or EnergyPlus (issue 41); `parallel-eplus serve` answers POST /act with the setpoints the in-process policy gives,
    with no torch in the process; `simulate` says which extra it needs."""
    from parallel_eplus.deploy.export.policy import export, reference_actions
    from parallel_eplus.deploy.serve.contract import Contract

    model = ROOT / "results" / "paper" / "models" / "paper-ca-co-fl-time"
    controller = tmp_path / "controller"
    export(model, controller)
    venv = tmp_path / "plant-room"
    subprocess.run([sys.executable, "-m", "venv", venv], check=True, capture_output=True)
    py, env = venv / "bin" / "python", {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    install = [py, "-m", "pip", "install", "-q", "--disable-pip-version-check", "--no-compile", f"{wheel}[serve]"]
    run = subprocess.run(install, capture_output=True, text=True, env=env, timeout=600)
    assert run.returncode == 0, run.stderr[-2000:]
    probe = (
        "import importlib.util as u; print(*(u.find_spec(m) is None for m in ('torch', 'gymnasium', 'pyenergyplus')))"
    )
    missing = subprocess.run([py, "-c", probe], capture_output=True, text=True, env=env, check=True).stdout.split()
    assert missing == ["True", "True", "True"]
    listing = "import importlib.metadata as m; print(*(d.metadata['Name'].lower() for d in m.distributions()))"
    serve = set(subprocess.run([py, "-c", listing], capture_output=True, text=True, env=env, check=True).stdout.split())
    assert {"onnxruntime", "fastapi", "uvicorn", "numpy", "parallel-eplus"} <= serve, sorted(serve)
    assert not HEAVY & serve, f"the serve extra pulls {sorted(HEAVY & serve)}"

    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    simulate = subprocess.run(
        [venv / "bin" / "parallel-eplus", "simulate", "--days", "1"],
        cwd=elsewhere, env=env, capture_output=True, text=True, timeout=120,
    )  # fmt: skip
    assert simulate.returncode == 2 and "Traceback" not in simulate.stderr, simulate.stderr[-2000:]
    assert "is not installed: pip install 'parallel-eplus[train]'" in simulate.stderr

    port = _free_port()
    log = tmp_path / "server.log"
    server = subprocess.Popen(
        [venv / "bin" / "parallel-eplus", "serve", controller, "--port", str(port)],
        cwd=elsewhere, env=env, stdout=log.open("w"), stderr=subprocess.STDOUT,
    )  # fmt: skip
    url = f"http://127.0.0.1:{port}"
    try:
        deadline = time.monotonic() + 60
        while True:
            try:
                with urllib.request.urlopen(url + "/health", timeout=5) as r:
                    health = json.loads(r.read())
                break
            except OSError:
                if server.poll() is not None or time.monotonic() > deadline:
                    raise AssertionError(f"the server did not start: {log.read_text()}") from None
                time.sleep(0.2)
        readings = {
            "outdoor_temp_c": 12.5, "west_temp_c": 23.1, "east_temp_c": 23.4,
            "power_w": 95000.0, "it_power_w": 70000.0, "hvac_power_w": 25000.0,
        }  # fmt: skip
        body = {"time": "2013-07-02T14:15:00", "sensors": readings}
        request = urllib.request.Request(
            url + "/act", data=json.dumps(body).encode(), headers={"Content-Type": "application/json"}
        )
        with urllib.request.urlopen(request, timeout=10) as r:
            setpoints = json.loads(r.read())["setpoints"]
        with urllib.request.urlopen(url + "/health", timeout=5) as r:
            health = json.loads(r.read())
    finally:
        server.terminate()
        server.wait(timeout=30)
    expected = reference_actions(model / "model.zip", Contract.read(controller).observation(body))[0]
    assert [s["value"] for s in setpoints.values()] == pytest.approx(expected, abs=1e-5)
    assert health["loaded"] == {"onnxruntime": True, "torch": False, "stable_baselines3": False}
    assert (health["act"], health["refused"]) == (1, 0)
