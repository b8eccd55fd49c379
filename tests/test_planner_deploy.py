"""Shipping the planner: export, the stateless server (last setpoints, forecast, plan), its fallback, the token,
and a served planner in closed loop with EnergyPlus against the in-process one."""

from __future__ import annotations

import datetime as dt
import json
import logging
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from parallel_eplus.buildings.building import load_building, weather_path
from parallel_eplus.buildings.weather.forecast import WEATHER, PerfectForecast
from parallel_eplus.deploy.export.policy import export
from parallel_eplus.deploy.serve.contract import Contract
from parallel_eplus.deploy.serve.own_setpoints import OwnSetpoints
from parallel_eplus.deploy.serve.planner_runtime import PlannerRuntime
from parallel_eplus.evaluation.controllers import http_controller
from parallel_eplus.evaluation.sweep import run_sweep
from parallel_eplus.learning.model_based.control.mpc import MPC
from parallel_eplus.learning.model_based.control.saved_planner import planner_controller
from parallel_eplus.learning.model_based.runtime.ensemble_graph import OnnxEnsemble, build_graph

from .serving import cli, get, serving

ROOT = Path(__file__).resolve().parents[1]
RUN = ROOT / "results/model-based/datacenter-2zone/runs/datacenter-2zone-mpc-seed0"  # committed, 52.5k steps
READINGS = {
    "outdoor_temp_c": 12.5, "west_temp_c": 23.1, "east_temp_c": 23.4,
    "power_w": 95000.0, "it_power_w": 70000.0, "hvac_power_w": 25000.0,
}  # fmt: skip
LAST = {"west_setpoint_c": 12.0, "east_setpoint_c": 12.0, "west_fan_kg_s": 4.0, "east_fan_kg_s": 4.0}
TOKEN = "kq3-planner-test-token-9f"


@pytest.fixture(scope="module")
def exported(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("planner")
    export(RUN, out, record_days=2)  # the own controls' record: two days of each training weather
    return out


@pytest.fixture(scope="module")
def client(exported):
    from fastapi.testclient import TestClient

    from parallel_eplus.deploy.serve.server import create_app

    with TestClient(create_app(exported)) as c:
        yield c


def forecast(when: dt.datetime, steps: int = 8, weather: str = "CA") -> dict:
    times = [when + dt.timedelta(minutes=15 * (k + 1)) for k in range(steps)]
    values = PerfectForecast(weather_path("datacenter-2zone", weather)).truth(times)
    return {n: values[:, i].tolist() for i, n in enumerate(WEATHER)}


def body(**changes) -> dict:
    when = dt.datetime(2021, 1, 5, 10, 0)
    out = {"time": when.isoformat(), "sensors": dict(READINGS), "last_setpoints": dict(LAST)}
    return {**out, "forecast": forecast(when), **changes}


def act(client, payload, **kw):
    return client.post("/act", content=json.dumps(payload), headers={"content-type": "application/json", **kw})


def test_the_ensemble_graph_predicts_what_the_torch_ensemble_does():
    mpc = MPC.load(RUN / "best/planner/planner.pt")
    forward = OnnxEnsemble(build_graph(mpc.model.arrays()))
    rng = np.random.default_rng(0)
    x = mpc.model.x_mean.numpy() + mpc.model.x_std.numpy() * rng.standard_normal((5, 64, forward.n_inputs))
    import torch as th

    with th.no_grad():
        xn = (th.as_tensor(x, dtype=th.float32) - mpc.model.x_mean) / mpc.model.x_std
        expected = (mpc.model(xn) * mpc.model.y_std + mpc.model.y_mean).numpy()
    got = forward(x.astype(np.float32))
    assert got.shape == (5, 64, mpc.layout.n_state)
    assert np.allclose(got, expected, rtol=1e-4, atol=1e-3 * np.abs(expected).max()), np.abs(got - expected).max()


@pytest.mark.slow
def test_export_writes_the_planner_and_checks_it_served_against_in_process(exported):
    files = ["controller.json", "ensemble.onnx", "planner.npz", "rollout.onnx"]
    assert sorted(p.name for p in exported.iterdir()) == files
    c = Contract.read(exported).data
    rollout = c["onnx"]["rollout"]  # the horizon in one call, which the served planner runs (checked: the same plans)
    assert (rollout["file"], rollout["horizon"], rollout["n_temps"]) == ("rollout.onnx", 8, 2)
    served = PlannerRuntime(exported, Contract.read(exported)).planner.forward.rollout(8, 2)
    assert served is not None and served.graph == (exported / "rollout.onnx").read_bytes()
    assert c["kind"] == "planner" and c["format"] == 2 and c["policy"]["algorithm"] == "mpc"
    assert c["export_check"]["decisions"] == 48 and c["export_check"]["max_abs_diff"] <= 1e-5
    assert [v["name"] for v in c["forecast"]["variables"]] == list(WEATHER) and c["forecast"]["steps"] == 8
    assert c["forecast"]["sensor"] == "outdoor_temp_c" and c["forecast"]["missing"] == "refuse"
    assert c["fallback"]["max_spread_k"] >= 0.5 and c["fallback"]["max_input_z"] == 6.0
    assert [o["initial"] for o in c["outputs"]] == [a.initial for a in load_building("datacenter-2zone").actions]
    own = np.load(exported / "planner.npz")["own_controls"]  # the own controls' setpoints step by step, as runs
    assert own.shape[1] == 4 and np.all((own[..., :2] >= 10) & (own[..., :2] <= 40))


@pytest.mark.slow
def test_the_same_request_gets_the_same_answer_and_its_plan_warm_starts_the_next(client):
    first, again = act(client, body()), act(client, body())
    assert first.status_code == 200, first.text
    answer = first.json()
    assert answer.pop("plan_ms") > 0
    assert {k: v for k, v in again.json().items() if k != "plan_ms"} == answer  # the sampler is seeded from the request
    assert answer["fallback"] is False and answer["forecast"] == "given"
    assert np.array(answer["plan"]).shape == (8, 4)
    for name, v in answer["setpoints"].items():
        assert v["unit"] in ("C", "kg/s") and np.isfinite(v["value"]), name
    warm = act(client, body(plan=answer["plan"]))
    assert warm.status_code == 200 and warm.json()["setpoints"] != answer["setpoints"]


BAD = {
    "no forecast": ({"forecast": None}, "forecast"),
    "a short forecast": (
        {"forecast": {**forecast(dt.datetime(2021, 1, 5, 10)), "outdoor_rh_pct": [50.0] * 3}},
        "forecast.outdoor_rh_pct",
    ),  # fmt: skip
    "a NaN in the forecast": (
        {"forecast": {**forecast(dt.datetime(2021, 1, 5, 10)), "outdoor_drybulb_c": [float("nan")] * 8}},
        "forecast.outdoor_drybulb_c[0]",
    ),
    "a forecast longer than the contract's horizon": (
        {"forecast": forecast(dt.datetime(2021, 1, 5, 10), steps=12)},
        "forecast.outdoor_drybulb_c",
    ),  # fmt: skip
    "a humidity no weather has, late in the forecast": (
        {"forecast": {**forecast(dt.datetime(2021, 1, 5, 10)), "outdoor_rh_pct": [50.0] * 7 + [130.0]}},
        "forecast.outdoor_rh_pct[7]",
    ),  # fmt: skip
    "a sun brighter than the sun, late in the forecast": (
        {"forecast": {**forecast(dt.datetime(2021, 1, 5, 10)), "global_horizontal_w_m2": [0.0] * 6 + [5000.0] * 2}},
        "forecast.global_horizontal_w_m2[6]",
    ),  # fmt: skip
    "a time with a UTC offset": ({"time": "2021-01-05T10:00:00+02:00"}, "time"),
    "a time in UTC": ({"time": "2021-01-05T08:00:00Z"}, "time"),
    "no last setpoints": ({"last_setpoints": None}, "last_setpoints"),
    "a last setpoint out of range": (
        {"last_setpoints": {**LAST, "west_fan_kg_s": 70.0}},
        "last_setpoints.west_fan_kg_s",
    ),  # fmt: skip
    "a plan of the wrong shape": ({"plan": [[0.0, 0.0]]}, "plan"),
    "no time": ({"time": None}, "time"),
    "a missing reading": (
        {"sensors": {k: v for k, v in READINGS.items() if k != "east_temp_c"}},
        "sensors.east_temp_c",
    ),  # fmt: skip
}


@pytest.mark.slow
@pytest.mark.parametrize("case", list(BAD))
def test_a_request_missing_what_the_planner_needs_is_refused_naming_it(client, case):
    changes, field = BAD[case]
    payload = {k: v for k, v in body(**changes).items() if v is not None}
    r = act(client, json.loads(json.dumps(payload).replace("NaN", "1e999")))
    assert r.status_code == 422 and r.json()["field"] == field, r.text
    assert act(client, body()).status_code == 200  # still serving


@pytest.mark.slow
def test_a_reading_far_from_the_data_falls_back_to_the_buildings_own_setpoints(client, exported, caplog):
    with caplog.at_level(logging.WARNING, logger="parallel_eplus.deploy.planner"):
        r = act(client, body(sensors={**READINGS, "west_temp_c": 35.0}))
    answer = r.json()
    assert r.status_code == 200 and answer["fallback"] is True and answer["plan"] is None
    assert "west_temp_c is" in answer["reason"] and "standard deviations" in answer["reason"]
    own = OwnSetpoints(dict(np.load(exported / "planner.npz")), 15)(dt.datetime(2021, 1, 5, 10))  # as recorded then
    assert [v["value"] for v in answer["setpoints"].values()] == pytest.approx(own.tolist())
    assert "fallback at 2021-01-05T10:00:00: west_temp_c" in caplog.text


@pytest.mark.slow
def test_a_forecast_that_contradicts_the_outdoor_sensor_falls_back(client):
    hot = forecast(dt.datetime(2021, 1, 5, 10))
    hot["outdoor_drybulb_c"] = [v + 15 for v in hot["outdoor_drybulb_c"]]
    answer = act(client, body(forecast=hot)).json()
    assert answer["fallback"] is True and "the forecast's first dry bulb" in answer["reason"]
    assert client.get("/health").json()["fallback"] >= 1


@pytest.mark.slow
def test_a_forecast_that_jumps_late_in_its_horizon_falls_back_naming_the_step(client):
    jumpy = forecast(dt.datetime(2021, 1, 5, 10))  # its first value agrees with the outdoor sensor
    jumpy["outdoor_drybulb_c"][5:] = [v + 22 for v in jumpy["outdoor_drybulb_c"][5:]]
    answer = act(client, body(forecast=jumpy)).json()
    assert answer["fallback"] is True, answer
    assert answer["reason"].startswith("forecast.outdoor_drybulb_c jumps 22.") and "to its value 5" in answer["reason"]


@pytest.mark.slow
def test_a_time_with_a_utc_offset_is_refused_saying_what_to_send(client):
    r = act(client, body(time="2021-01-05T10:00:00+02:00"))
    assert r.status_code == 422 and "UTC offset (+0200)" in r.json()["error"]
    assert "local standard time without one" in r.json()["error"]


@pytest.mark.slow
def test_fallback_reasons_name_what_the_contract_names(client, exported):
    """Every reason names a reading, a last setpoint or a forecast variable as the contract does, with its value in
    the contract's units; never a variable of the model's own (non_hvac_w, outdoor_rh, global_horizontal_kw_m2)."""
    contract = Contract.read(exported).data
    names = {i["name"] for i in contract["inputs"]} | {f"last_setpoints.{o['name']}" for o in contract["outputs"]}
    names |= {f"forecast.{v['name']} (its first value)" for v in contract["forecast"]["variables"]}
    names.add("power_w - hvac_power_w")  # the power that is not HVAC's, from two readings
    cold = forecast(dt.datetime(2021, 1, 5, 10))
    cold["outdoor_drybulb_c"] = [-45.0] * 8
    cases = {
        "power_w - hvac_power_w is 225000 W": body(sensors={**READINGS, "power_w": 250000.0}),
        "forecast.outdoor_drybulb_c (its first value) is -45 C": body(forecast=cold,
                                                                       sensors={**READINGS, "outdoor_temp_c": -20.0}),
        "west_temp_c is 35 C": body(sensors={**READINGS, "west_temp_c": 35.0}),
    }  # fmt: skip
    for expected, payload in cases.items():
        answer = act(client, payload).json()
        assert answer["fallback"] is True and answer["reason"].startswith(expected + ", "), answer
        assert answer["reason"].split(" is ")[0] in names
        for internal in ("non_hvac_w", "outdoor_rh ", "outdoor_rh,", "kw_m2", "last_west", "it_load"):
            assert internal not in answer["reason"]


@pytest.mark.slow
def test_the_bearer_scheme_is_case_insensitive(exported):
    """RFC 7235: `bearer`, `BEARER` and `Bearer` are one scheme; another scheme, or the token alone, is refused."""
    from fastapi.testclient import TestClient

    from parallel_eplus.deploy.serve.server import create_app

    with TestClient(create_app(exported, token=TOKEN)) as c:
        for scheme in ("Bearer", "bearer", "BEARER", "bEaReR"):
            assert c.get("/health", headers={"authorization": f"{scheme} {TOKEN}"}).status_code == 200, scheme
        for header in (f"Basic {TOKEN}", TOKEN, f"bearer {TOKEN}x", "bearer"):
            r = c.get("/health", headers={"authorization": header})
            assert r.status_code == 401 and r.json()["field"] == "authorization", header


@pytest.fixture(scope="module")
def quiet_persistence(tmp_path_factory) -> tuple[Path, subprocess.CompletedProcess]:
    """`parallel-eplus export RUN --persistence --quiet`, a process of its own: the directory and what it wrote."""
    out = tmp_path_factory.mktemp("persistence") / "out"
    r = subprocess.run([sys.executable, "-m", "parallel_eplus.cli", "export", str(RUN), "-o", str(out),
                        "--record-days", "1", "--workers", "1", "--persistence", "--quiet"], capture_output=True,
                       text=True, timeout=600)  # fmt: skip
    return out, r


@pytest.mark.slow
def test_a_planner_exported_with_persistence_answers_without_a_forecast_and_says_so(quiet_persistence):
    out, r = quiet_persistence
    assert r.returncode == 0, r.stderr
    from fastapi.testclient import TestClient

    from parallel_eplus.deploy.serve.server import create_app

    with TestClient(create_app(out)) as c:
        answer = act(c, {k: v for k, v in body().items() if k != "forecast"}).json()
    assert answer["forecast"] == "persistence" and answer["fallback"] is False


@pytest.mark.slow
def test_with_a_token_every_request_needs_it_and_the_log_never_shows_it(exported, caplog):
    from fastapi.testclient import TestClient

    from parallel_eplus.deploy.serve.server import create_app

    with caplog.at_level(logging.INFO), TestClient(create_app(exported, token=TOKEN)) as c:
        missing = act(c, body())
        wrong = act(c, body(), authorization="Bearer not-the-token")
        right = act(c, body(), authorization=f"Bearer {TOKEN}")
        health = c.get("/health")
    assert missing.status_code == 401 and missing.json()["field"] == "authorization"
    assert "missing" in missing.json()["error"] and missing.headers["www-authenticate"] == "Bearer"
    assert wrong.status_code == 401 and "wrong token" in wrong.json()["error"]
    assert right.status_code == 200 and health.status_code == 401
    assert "POST /act 401" in caplog.text and "POST /act 200" in caplog.text
    assert TOKEN not in caplog.text


@pytest.mark.slow
def test_serving_off_loopback_needs_a_token_file_and_tls_needs_both_files(exported, tmp_path):
    r = cli("serve", str(exported), "--host", "0.0.0.0")
    assert r.returncode == 2 and "--token-file" in r.stderr
    (tmp_path / "empty").write_text("\n")
    r = cli("serve", str(exported), "--host", "0.0.0.0", "--token-file", str(tmp_path / "empty"))
    assert r.returncode == 2 and "is empty" in r.stderr
    r = cli("serve", str(exported), "--ssl-keyfile", str(tmp_path / "key.pem"))
    assert r.returncode == 2 and "both --ssl-keyfile and --ssl-certfile" in r.stderr


@pytest.mark.slow
def test_export_quiet_writes_no_progress_bar(quiet_persistence):
    out, r = quiet_persistence
    assert r.returncode == 0, r.stderr
    assert (out / "controller.json").is_file()
    output = r.stdout + r.stderr
    assert "step/s" not in output and "\r" not in output and "%|" not in output, output[-2000:]
    assert len(output) < 4000, output[-2000:]  # the log's lines, not a bar redrawn hundreds of times


@pytest.mark.slow
def test_a_short_or_exposed_token_is_refused_and_plain_http_off_loopback_warns(exported, tmp_path, caplog):
    """A token shorter than 16 characters, or in a file others may read, is refused before anything listens (on
    loopback too); a token sent over plain HTTP off loopback is a loud warning. Never the token in the message."""
    from parallel_eplus.deploy.serve.server import check_access

    short, loose, good = tmp_path / "short", tmp_path / "loose", tmp_path / "good"
    short.write_text("k\n")
    short.chmod(0o600)
    loose.write_text(TOKEN + "\n")
    loose.chmod(0o644)
    good.write_text(TOKEN + "\n")
    good.chmod(0o600)
    r = cli("serve", str(exported), "--token-file", str(short))
    assert r.returncode == 2 and "the token has 1 characters; at least 16" in r.stderr, r.stderr
    r = cli("serve", str(exported), "--token-file", str(loose))
    assert r.returncode == 2 and "(mode 644): chmod 600" in r.stderr and TOKEN not in r.stderr, r.stderr
    with caplog.at_level(logging.WARNING, logger="parallel_eplus.deploy.serve.server"):
        assert check_access("0.0.0.0", good, tls=False) == TOKEN
        assert "PLAIN HTTP on 0.0.0.0" in caplog.text and TOKEN not in caplog.text
        caplog.clear()
        assert check_access("0.0.0.0", good, tls=True) == TOKEN
        assert check_access("127.0.0.1", None, tls=False) is None
    assert "PLAIN HTTP" not in caplog.text


@pytest.mark.slow
def test_over_tls_with_a_token(exported, tmp_path):
    """uvicorn's TLS with a self-signed certificate (openssl), and the token, as a plant room would run it."""
    key, cert, token = tmp_path / "key.pem", tmp_path / "cert.pem", tmp_path / "token"
    subprocess.run(["openssl", "req", "-x509", "-newkey", "rsa:2048", "-nodes", "-keyout", key, "-out", cert,
                    "-days", "1", "-subj", "/CN=127.0.0.1"], check=True, capture_output=True)  # fmt: skip
    token.write_text(TOKEN + "\n")
    token.chmod(0o600)
    import ssl
    import urllib.error
    import urllib.request

    context = ssl.create_default_context(cafile=str(cert))
    context.check_hostname = False
    args = ("--token-file", str(token), "--ssl-keyfile", str(key), "--ssl-certfile", str(cert))
    with serving(exported, tmp_path / "server.log", *args, scheme="https", context=context,
                 headers={"Authorization": f"Bearer {TOKEN}"}) as url:  # fmt: skip
        assert url.startswith("https://")
        assert get(url + "/health", {"Authorization": f"Bearer {TOKEN}"}, context)["kind"] == "planner"
        with pytest.raises(urllib.error.HTTPError) as refused:
            get(url + "/health", {}, context)
        assert refused.value.code == 401
        refused.value.close()
    assert TOKEN not in (tmp_path / "server.log").read_text()


@pytest.mark.slow
def test_a_served_planner_writes_nothing_to_the_users_home(exported, tmp_path, monkeypatch):
    """onnxruntime writes a device id and a telemetry database under ~/.cache when imported, unless told not to:
    the server, started as a user would (no ORT_DISABLE_TELEMETRY of theirs), leaves HOME as it found it."""
    import urllib.request

    home = tmp_path / "home"
    home.mkdir()
    monkeypatch.setenv("HOME", str(home))
    monkeypatch.delenv("XDG_CACHE_HOME", raising=False)
    monkeypatch.delenv("ORT_DISABLE_TELEMETRY", raising=False)
    with serving(exported, tmp_path / "server.log") as url:
        for _ in range(3):
            request = urllib.request.Request(url + "/act", json.dumps(body()).encode(),
                                             {"Content-Type": "application/json"})  # fmt: skip
            with urllib.request.urlopen(request, timeout=30) as r:
                assert json.loads(r.read())["fallback"] is False
    assert [str(p.relative_to(home)) for p in home.rglob("*")] == []


@pytest.mark.slow
def test_evaluate_sends_the_token_from_a_file_or_the_environment_and_never_shows_it(
    exported, tmp_path, monkeypatch, caplog, capfd
):
    from parallel_eplus.evaluation.http_controller import TOKEN_VARIABLE, client_token

    token, wrong, log = tmp_path / "token", tmp_path / "wrong", tmp_path / "server.log"
    token.write_text(TOKEN + "\n")
    token.chmod(0o600)
    wrong.write_text("not-the-token-0123456789\n")
    evaluate = ("evaluate", "--building", "datacenter-2zone", "--weathers", "CA", "--run-days", "1", "--workers", "1",
                "--quiet")  # fmt: skip

    def run(*args: str, **extra: str) -> subprocess.CompletedProcess:
        """`parallel-eplus evaluate ARGS` in this process (a fresh interpreter pays torch's import each time), with
        `extra` as its only token variable: its exit code, what it printed, and its log at INFO with its stderr."""
        with monkeypatch.context() as m, caplog.at_level(logging.INFO):
            m.delenv(TOKEN_VARIABLE, raising=False)
            for name, value in extra.items():
                m.setenv(name, value)
            done = cli(*evaluate, *args)
        printed = capfd.readouterr()
        return subprocess.CompletedProcess(done.args, done.returncode, printed.out, done.stderr + printed.err)

    with serving(exported, log, "--token-file", str(token), headers={"Authorization": f"Bearer {TOKEN}"}) as url:
        none = run("--controller-url", url, "--out", str(tmp_path / "none"))
        assert none.returncode == 2 and "needs a token: give --token-file FILE" in none.stderr, none.stderr
        assert TOKEN_VARIABLE in none.stderr
        refused = run("--controller-url", url, "--token-file", str(wrong), "--out", str(tmp_path / "wrong"),
                      **{TOKEN_VARIABLE: TOKEN})  # the flag, when given, is what is sent  # fmt: skip
        assert refused.returncode == 2 and "refused the token given" in refused.stderr, refused.stderr
        done = run("--controller-url", url, "--token-file", str(token), "--out", str(tmp_path / "done"))
        assert done.returncode == 0, done.stderr[-3000:]
        assert "MPC planner via HTTP (datacenter-2zone-mpc-seed0)" in done.stdout
        assert re.search(r": 96 POST /act, p50 [\d.]+ ms, p99 [\d.]+ ms", done.stderr), done.stderr[-2000:]
        monkeypatch.setenv(TOKEN_VARIABLE, TOKEN)  # the environment's, without the flag
        assert client_token(None) == TOKEN
        assert http_controller(url, client_token(None)).served["model"] == "planner.pt"
        assert get(url + "/health", {"Authorization": f"Bearer {TOKEN}"})["act"] == 96
    for r in (none, refused, done):
        assert TOKEN not in r.stdout + r.stderr
    assert TOKEN not in caplog.text
    assert TOKEN not in log.read_text() and log.read_text().count("POST /act 200") == 96


@pytest.mark.slow
def test_evaluate_refuses_a_policy_that_is_not_the_served_controller(exported, tmp_path, caplog):
    """`--policy RUN` of a model-based run is its distilled network; `export RUN` serves its planner: side by side
    they are refused, naming the --policy that is the served one; another run's policy beside it is a warning."""
    from parallel_eplus.evaluation.controllers import check_same_controllers, policy_controllers

    with serving(exported, tmp_path / "server.log") as url:
        r = cli("evaluate", "--policy", str(RUN), "--controller-url", url, "--building", "datacenter-2zone",
                "--weathers", "CA", "--run-days", "1", "--out", str(tmp_path / "out"))  # fmt: skip
        assert r.returncode == 2 and "is not the controller" in r.stderr, r.stderr
        assert f"give --policy {RUN / 'best' / 'planner'} " in r.stderr
        caplog.clear()  # the refusal above
        served = http_controller(url)
        check_same_controllers([planner_controller(str(RUN / "best" / "planner"))], [served])  # the same: quiet
        assert not caplog.records
        paper = ROOT / "results/paper/models/paper-ca-co-fl-time"
        with caplog.at_level(logging.WARNING, logger="parallel_eplus.evaluation.controllers"):
            check_same_controllers(policy_controllers(str(paper)), [served])
        assert "which no --policy names" in caplog.text
    assert not (tmp_path / "out").exists() or not any((tmp_path / "out").iterdir())


@pytest.mark.slow
def test_closed_loop_through_the_served_planner_equals_the_in_process_planner(exported, tmp_path, no_leaks):
    log = tmp_path / "server.log"
    with serving(exported, log) as url:
        health = get(url + "/health")
        assert health["loaded"] == {"onnxruntime": True, "torch": False, "stable_baselines3": False}
        planner = planner_controller(f"{RUN / 'best/planner'}=Planner")
        df = run_sweep([planner, http_controller(url)], ["CA"], 1, 2, tmp_path / "eval", progress=False,
                       building="datacenter-2zone")  # fmt: skip
        assert get(url + "/health")["act"] == 96
    in_process, over_http = (pd.read_parquet(Path(d) / "steps.parquet") for d in df.episode_dir)
    assert len(in_process) == 96
    pd.testing.assert_frame_equal(in_process, over_http, check_exact=True)  # every reading and setpoint, every step
    assert log.read_text().count("POST /act 200") == 96
