"""Deploying a trained policy: export parity, the HTTP server's contract and refusals, closed loop with EnergyPlus."""

from __future__ import annotations

import json
from pathlib import Path

import pandas as pd
import pytest

from parallel_eplus.deploy.export.parity import observations, replay
from parallel_eplus.deploy.export.policy import export, reference_actions
from parallel_eplus.deploy.serve.contract import Contract
from parallel_eplus.evaluation.controllers import http_controller, policy_controller
from parallel_eplus.evaluation.sweep import run_sweep
from parallel_eplus.learning.settings import SACSettings
from parallel_eplus.training.config import TrainConfig
from parallel_eplus.training.train import train

from .serving import cli, free_port, get, serving

ROOT = Path(__file__).resolve().parents[1]
MODELS = ROOT / "results" / "paper" / "models"  # policies trained for results/paper (a year each, committed)
READINGS = {
    "outdoor_temp_c": 12.5, "west_temp_c": 23.1, "east_temp_c": 23.4,
    "power_w": 95000.0, "it_power_w": 70000.0, "hvac_power_w": 25000.0,
}  # fmt: skip


@pytest.fixture(scope="module")
def controller(tmp_path_factory) -> Path:
    """The paper's TRPO with time features (committed in results/paper/models), exported."""
    out = tmp_path_factory.mktemp("controller")
    export(MODELS / "paper-ca-co-fl-time", out)
    return out


@pytest.fixture(scope="module")
def client(controller):
    from fastapi.testclient import TestClient

    from parallel_eplus.deploy.serve.server import create_app

    with TestClient(create_app(controller)) as c:
        yield c


def act(client, body, **kw):
    return client.post("/act", content=json.dumps(body), headers={"content-type": "application/json"}, **kw)


def test_contract_names_every_input_and_output_with_units_bounds_and_provenance(controller):
    c = json.loads((controller / "controller.json").read_text())
    assert [i["name"] for i in c["inputs"]] == [*READINGS, "hour_sin", "hour_cos", "weekday_sin", "weekday_cos"]
    west = c["inputs"][1]
    assert (west["variable"], west["key"], west["unit"]) == ("Zone Mean Air Temperature", "West Zone", "C")
    assert [(o["name"], o["unit"], o["low"], o["high"]) for o in c["outputs"]] == [
        ("west_setpoint_c", "C", 10.0, 40.0), ("east_setpoint_c", "C", 10.0, 40.0),
        ("west_fan_kg_s", "kg/s", 1.75, 7.0), ("east_fan_kg_s", "kg/s", 1.75, 7.0),
    ]  # fmt: skip
    assert c["outputs"][0]["actuators"][0]["key"] == "West Zone DEC Outlet Node"
    assert c["control_step_s"] == 900 and c["time"]["required"]
    assert c["building"]["name"] == "datacenter-2zone" and len(c["building"]["sha256"]) == 64
    assert c["policy"]["algorithm"] == "trpo" and c["policy"]["seed"] == 0
    assert set(c["results"]["last_episode_per_weather"]) == {"CA", "CO", "FL"}
    assert c["export_check"]["max_abs_diff"] <= 1e-5


def test_server_acts_in_physical_units_as_the_policy_does_in_process(client, controller):
    r = act(client, {"time": "2013-07-02T14:15:00", "sensors": READINGS})
    assert r.status_code == 200, r.text
    setpoints = r.json()["setpoints"]
    assert list(setpoints) == ["west_setpoint_c", "east_setpoint_c", "west_fan_kg_s", "east_fan_kg_s"]
    assert setpoints["west_fan_kg_s"]["unit"] == "kg/s" and 1.75 <= setpoints["west_fan_kg_s"]["value"] <= 7.0
    obs = Contract.read(controller).observation({"time": "2013-07-02T14:15:00", "sensors": READINGS})
    expected = reference_actions(MODELS / "paper-ca-co-fl-time" / "model.zip", obs)[0]
    assert [s["value"] for s in setpoints.values()] == pytest.approx(expected, abs=1e-5)
    assert client.get("/contract").json()["policy"]["run"] == "paper-ca-co-fl-time"
    assert client.get("/health").json()["status"] == "ok"


def with_reading(name, value):
    return {"time": "2013-07-02T14:15:00", "sensors": {**READINGS, name: value}}


BAD = {
    "missing sensor": (
        {"time": "2013-07-02T14:15:00", "sensors": {"outdoor_temp_c": 12.5}},
        422,
        "sensors.west_temp_c",
    ),
    "NaN": ('{"time": "2013-07-02T14:15:00", "sensors": {"outdoor_temp_c": NaN}}', 422, "sensors.outdoor_temp_c"),
    "out of range": (with_reading("west_temp_c", 80.0), 422, "sensors.west_temp_c"),
    "wrong unit": (with_reading("west_temp_c", {"value": 296.2, "unit": "K"}), 422, "sensors.west_temp_c"),
    "unknown name": (
        {"time": "2013-07-02T14:15:00", "sensors": {**READINGS, "west_temp": 23}},
        422,
        "sensors.west_temp",
    ),
    "not a number": (with_reading("power_w", "95 kW"), 422, "sensors.power_w"),
    "no time": ({"sensors": READINGS}, 422, "time"),
    "bad time": ({"time": "tomorrow", "sensors": READINGS}, 422, "time"),
    "not JSON": ("{sensors: 1", 400, "body"),
    "not an object": ("[1, 2]", 400, "body"),
}


@pytest.mark.parametrize("case", BAD)
def test_bad_input_is_refused_naming_the_field_and_the_server_keeps_serving(client, case):
    body, status, field = BAD[case]
    content = body if isinstance(body, str) else json.dumps(body)
    r = client.post("/act", content=content, headers={"content-type": "application/json"})
    assert r.status_code == status, r.text
    assert r.json()["field"] == field and field in r.json()["error"]
    assert act(client, {"time": "2013-07-02T14:15:00", "sensors": READINGS}).status_code == 200


def test_wrong_content_type_and_huge_body_are_refused(client):
    r = client.post("/act", content=json.dumps({"sensors": READINGS}), headers={"content-type": "text/plain"})
    assert r.status_code == 415 and r.json()["field"] == "content-type"
    huge = json.dumps({"time": "2013-07-02T14:15:00", "sensors": READINGS, "pad": "x" * 200_000})
    r = client.post("/act", content=huge, headers={"content-type": "application/json"})
    assert r.status_code == 413 and r.json()["field"] == "body"

    def chunks():  # no Content-Length: the body is cut off as it streams in
        for _ in range(100):
            yield b"x" * 4096

    r = client.post("/act", content=chunks(), headers={"content-type": "application/json"})
    assert r.status_code == 413
    assert client.get("/health").json()["refused"] >= 3


def test_requests_are_logged(client, caplog):
    with caplog.at_level("INFO", logger="parallel_eplus.deploy.serve.server"):
        act(client, {"time": "2013-07-02T14:15:00", "sensors": READINGS})
        act(client, {"sensors": {}})
    lines = [r.getMessage() for r in caplog.records]
    assert any(line.startswith("POST /act 200") for line in lines)
    assert any(line.startswith("POST /act 422") for line in lines)


def test_a_residual_policy_is_refused_with_the_reason(tmp_path):
    with pytest.raises(ValueError, match="corrects the rule-based controller"):
        export(MODELS / "residual-demand", tmp_path / "out")
    assert not (tmp_path / "out" / "controller.onnx").exists()


def test_a_policy_observing_forecasts_is_refused_with_the_reason(tmp_path):
    import shutil

    run = tmp_path / "forecast"
    shutil.copytree(MODELS / "paper-ca-co-fl-10m", run)
    config = json.loads((run / "config.json").read_text())
    (run / "config.json").write_text(json.dumps({**config, "forecast_hours": 6}))
    with pytest.raises(ValueError, match="6 hours of weather forecast"):
        export(run, tmp_path / "out")


def test_a_controller_edited_after_export_is_refused(controller, tmp_path):
    from parallel_eplus.deploy.serve.server import create_app

    copy = tmp_path / "copy"
    copy.mkdir()
    (copy / "controller.json").write_text((controller / "controller.json").read_text())
    (copy / "controller.onnx").write_bytes((controller / "controller.onnx").read_bytes() + b"\0")
    with pytest.raises(ValueError, match="sha256"):
        create_app(copy)


@pytest.mark.slow
@pytest.mark.parametrize("algorithm", ["trpo", "ppo", "sac"])
def test_exported_controller_gives_the_policys_setpoints_over_a_recorded_episode(tmp_path, no_leaks, algorithm):
    """A freshly trained policy of each algorithm (TRPO with the schedule features too), exported; its setpoints on
    every step of a day `evaluate` recorded in process equal the recorded ones within 1e-5."""
    cfg = TrainConfig(
        workers=1, weathers=["CO"], run_days=1, timesteps=192 if algorithm == "sac" else 96, batch_size=96,
        algorithm=algorithm, run_name=algorithm, time_features=True, schedule_features=algorithm == "trpo",
        sac=SACSettings(learning_starts=96, batch_size=32, buffer_size=1000),
        runs_dir=str(tmp_path / "runs"), tensorboard_dir=str(tmp_path / "tb"),
    )  # fmt: skip
    model = train(cfg, progress=False)
    out = tmp_path / "controller"
    r = cli("export", str(model.parent), "-o", str(out))
    assert r.returncode == 0, r.stderr
    df = run_sweep([policy_controller(str(model))], ["CO"], 1, 1, tmp_path / "eval", progress=False)
    steps = pd.read_parquet(Path(df.episode_dir[0]) / "steps.parquet")
    result = replay(out, steps)
    assert result["steps"] == 95 and max(result["max_abs_diff"].values()) <= 1e-5, result
    features = Contract.read(out).features
    assert features[:4] == ["hour_sin", "hour_cos", "weekday_sin", "weekday_cos"]
    assert ("it_load" in features) == (algorithm == "trpo")
    assert observations(Contract.read(out), steps).shape == (96, 6 + len(features))


@pytest.fixture
def served(controller, tmp_path):
    log = tmp_path / "server.log"
    with serving(controller, log) as url:
        yield url, log


@pytest.mark.slow
def test_closed_loop_through_the_server_equals_the_in_process_episode_step_by_step(tmp_path, served, no_leaks):
    url, log = served
    health = get(url + "/health")
    assert health["loaded"] == {"onnxruntime": True, "torch": False, "stable_baselines3": False}
    policy = policy_controller(str(MODELS / "paper-ca-co-fl-time"))
    df = run_sweep([policy, http_controller(url)], ["CA"], 1, 2, tmp_path / "eval", progress=False)
    assert df.controller.tolist() == ["TRPO (CA-CO-FL)", "TRPO via HTTP (paper-ca-co-fl-time)"]
    in_process, over_http = (pd.read_parquet(Path(d) / "steps.parquet") for d in df.episode_dir)
    assert len(in_process) == 96
    pd.testing.assert_frame_equal(in_process, over_http, check_exact=True)  # every reading and setpoint, every step
    figures = ["power_kw", "in_band_pct", "west_temp_mean", "east_temp_mean"]
    assert df[figures].iloc[0].tolist() == df[figures].iloc[1].tolist()
    assert get(url + "/health")["act"] == 96
    assert log.read_text().count("POST /act 200") == 96  # every request logged
    assert not get(url + "/health")["loaded"]["torch"]


@pytest.mark.slow
def test_evaluate_with_no_server_at_the_url_says_so(tmp_path):
    r = cli(
        "evaluate", "--controller-url", f"http://127.0.0.1:{free_port()}", "--run-days", "1", "--out", str(tmp_path)
    )
    assert r.returncode == 2 and "is it serving?" in r.stderr
    r = cli("evaluate", "--controller-url", "ftp://host", "--out", str(tmp_path))
    assert r.returncode == 2 and "give http://HOST:PORT" in r.stderr
    assert not any(tmp_path.iterdir())


@pytest.mark.slow
def test_export_command_writes_both_files_and_refuses_what_it_cannot_export(tmp_path):
    r = cli("export", str(MODELS / "ppo-ca-co-fl-time"), "-o", str(tmp_path / "ppo"))
    assert r.returncode == 0, r.stderr
    assert sorted(p.name for p in (tmp_path / "ppo").iterdir()) == ["controller.json", "controller.onnx"]
    assert Contract.read(tmp_path / "ppo").data["policy"]["algorithm"] == "ppo"
    r = cli("export", str(MODELS / "residual-demand"), "-o", str(tmp_path / "res"))
    assert r.returncode == 2 and "corrects the rule-based controller" in r.stderr
    r = cli("export", str(tmp_path / "nothing"), "-o", str(tmp_path / "x"))
    assert r.returncode == 2 and "no trained policy" in r.stderr
    r = cli("serve", str(tmp_path / "nothing"))
    assert r.returncode == 2 and "controller.json not found" in r.stderr


@pytest.mark.slow
def test_a_policy_whose_thermostats_cross_is_exported_and_served_uncrossed(tmp_path, no_leaks):
    """Bounds that overlap (heating 24-26 C, cooling 20-24 C) make an untrained policy's heating setpoint sit above
    its cooling one; the env lowers it to the cooling setpoint, and the exported graph and the served answer must
    too: the contract names the pair, and the graph replays the recorded (uncrossed) setpoints within 1e-5."""
    from parallel_eplus.buildings.resources import spec_file
    from parallel_eplus.deploy.serve.runtime import load_runtime

    text = spec_file("office-small").read_text()
    text = text.replace("low = 23.0\nhigh = 30.0\ninitial = 24.0", "low = 20.0\nhigh = 24.0\ninitial = 24.0", 1)
    text = text.replace("low = 15.0\nhigh = 22.0\ninitial = 21.0", "low = 24.0\nhigh = 26.0\ninitial = 24.0", 1)
    spec = tmp_path / "office-crossed.toml"
    spec.write_text(text)
    cfg = TrainConfig(
        workers=1,
        weathers=["CA"],
        run_days=1,
        timesteps=144,
        batch_size=144,
        building=str(spec),
        run_name="crossed",
        runs_dir=str(tmp_path / "runs"),
        tensorboard_dir=str(tmp_path / "tb"),
    )
    model = train(cfg, progress=False)
    out = tmp_path / "controller"
    export(model.parent, out)
    contract = Contract.read(out)
    assert [o.get("at_most") for o in contract.outputs] == [None, ["cooling_setpoint_c"]]
    df = run_sweep([policy_controller(str(model))], ["CA"], 1, 1, tmp_path / "eval", progress=False, building=str(spec))
    steps = pd.read_parquet(Path(df.episode_dir[0]) / "steps.parquet")
    assert (steps.heating_setpoint_c == steps.cooling_setpoint_c).mean() > 0.5  # the policy crosses them, mostly
    result = replay(out, steps)
    assert result["steps"] == 143 and max(result["max_abs_diff"].values()) <= 1e-5, result
    row = steps.iloc[50]
    readings = {s["name"]: float(row[s["name"]]) for s in contract.sensors}
    answer = load_runtime(out).act({"sensors": readings, "time": pd.Timestamp(row["time"]).isoformat()})
    assert answer["setpoints"]["heating_setpoint_c"]["value"] <= answer["setpoints"]["cooling_setpoint_c"]["value"]
