"""`parallel-eplus boptest`: BOPTEST's service API (ibpsa/project1-boptest, service/web/server/docs/openapi.yaml),
driven by a client written from that description over a real socket, on the small office (10-minute timesteps,
Chicago's weather) and real EnergyPlus: one server for the module (2 workers, a 6 s idle timeout), each test its own
BOPTEST tests, each EnergyPlus run a few hours of January.
"""

from __future__ import annotations

import http.client
import json
import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

from tests.conftest import our_pipe_dirs, our_processes
from tests.serving import cli, free_port

DAY = 86400
START = 10 * DAY + 2 * 3600  # January 11, 02:00: the office's setback (heating 15.6 °C), its furnaces idle
IDLE_S = 6.0
TESTCASE = "office-small"


class Boptest:
    """BOPTEST's API as its OpenAPI description states it: one kept-alive connection (one per thread)."""

    def __init__(self, port: int):
        self.conn = http.client.HTTPConnection("127.0.0.1", port, timeout=180)

    def request(self, method: str, path: str, body=None, raw: bytes | None = None) -> tuple[int, object]:
        data = raw if raw is not None else None if body is None else json.dumps(body).encode()
        headers = {"Content-Type": "application/json"} if data is not None else {}
        try:
            self.conn.request(method, path, body=data, headers=headers)
            r = self.conn.getresponse()
        except (http.client.RemoteDisconnected, ConnectionResetError, BrokenPipeError):  # kept alive too long
            self.conn.close()
            self.conn.request(method, path, body=data, headers=headers)
            r = self.conn.getresponse()
        text = r.read().decode()
        kind = r.getheader("content-type", "")
        return r.status, json.loads(text) if kind.startswith("application/json") else text

    def ok(self, method: str, path: str, body=None):
        status, answer = self.request(method, path, body)
        assert status == 200, (path, answer)
        if isinstance(answer, dict) and "payload" in answer:
            assert answer["status"] == 200 and isinstance(answer["message"], str), answer
            return answer["payload"]
        return answer

    def select(self, testcase: str = TESTCASE, **options) -> str:
        return self.ok("POST", f"/testcases/{testcase}/select", options)["testid"]

    def initialize(self, testid: str, start: float, warmup: float) -> dict:
        return self.ok("PUT", f"/initialize/{testid}", {"start_time": start, "warmup_period": warmup})

    def advance(self, testid: str, u: dict | None = None) -> dict:
        return self.ok("POST", f"/advance/{testid}", u or {})

    def stop(self, testid: str) -> None:
        assert self.ok("PUT", f"/stop/{testid}") == "OK"


@pytest.fixture(scope="module")
def server(tmp_path_factory):
    """The server as a user starts it, on a free loopback port; every process and pipe of it gone at its end."""
    before = our_pipe_dirs()
    port, folder = free_port(), tmp_path_factory.mktemp("boptest")
    cache = folder / "cache"
    # BOPTEST's test period of the office on IL as `evaluate --scenario` keeps it (its year of own controls is
    # test_evaluate's to check): a one-day warm-up here, to keep the test short
    period = {"scenario": "peak_heat", "day": 26, "start_day": 19, "weekday": "Thursday", "run_days": 8,
              "warmup_days": 1, "first_scored": "2013-01-20"}  # fmt: skip
    (cache / TESTCASE).mkdir(parents=True)
    (cache / TESTCASE / "scenarios.json").write_text(json.dumps({"IL": {"peak_heat": period}}))
    log = folder / "server.log"
    proc = subprocess.Popen(
        [sys.executable, "-m", "parallel_eplus.cli", "boptest", "--port", str(port), "--workers", "2",
         "--idle-timeout", str(IDLE_S), "--cache", str(cache)],
        stdout=log.open("w"), stderr=subprocess.STDOUT, text=True,
    )  # fmt: skip
    deadline = time.monotonic() + 120
    while True:
        try:
            Boptest(port).ok("GET", "/version")
            break
        except OSError:
            if proc.poll() is not None or time.monotonic() > deadline:
                raise AssertionError(f"the server did not start: {log.read_text()}") from None
            time.sleep(0.3)
    yield port, proc, log
    proc.send_signal(signal.SIGTERM)
    assert proc.wait(timeout=60) == 0, log.read_text()[-3000:]
    assert our_processes() == []
    assert our_pipe_dirs() - before == set()


def energyplus_of(server_pid: int) -> list[int]:
    """The server's EnergyPlus processes (its children running the EnergyPlus side)."""
    out = subprocess.run(["pgrep", "-P", str(server_pid), "-f", "eplus_side.callback"], capture_output=True, text=True)
    return [int(p) for p in out.stdout.split()]


def test_metadata_as_boptest_names_it_in_si_units(server):
    port, _, _ = server
    c = Boptest(port)
    names = {t["testcaseid"] for t in c.ok("GET", "/testcases")}
    assert {"office-small", "office-medium", "datacenter-2zone", "datacenter-crac"} <= names
    assert c.ok("GET", "/version")["version"]
    testid, other = c.select(weather="IL"), c.select(weather="IL")
    assert len(testid) == 32 and testid != other  # random ids, one per selection
    c.stop(other)  # its worker free at once for the next test, not after the idle timeout
    assert c.ok("GET", f"/name/{testid}") == {"name": TESTCASE}
    assert c.ok("GET", f"/status/{testid}") == "Running"
    inputs = c.ok("GET", f"/inputs/{testid}")
    assert inputs["cooling_setpoint_u"] == {"Unit": "K", "Minimum": pytest.approx(296.15),
                                            "Maximum": pytest.approx(303.15),
                                            "Description": inputs["cooling_setpoint_u"]["Description"]}  # fmt: skip
    assert "Cooling Setpoint on Core_ZN" in inputs["cooling_setpoint_u"]["Description"]
    assert set(inputs) == {"cooling_setpoint_u", "cooling_setpoint_activate", "heating_setpoint_u",
                           "heating_setpoint_activate"}  # fmt: skip
    y = c.ok("GET", f"/measurements/{testid}")
    assert y["core_temp_y"]["Unit"] == "K" and y["power_y"]["Unit"] == "W"
    assert y["setpoint_htgsetp_sch_y"]["Unit"] == "K"  # the thermostat's own schedule, which tdis reads
    assert y["hvac_naturalgas_y"]["Unit"] == "W"  # the KPIs' gas meter
    f = c.ok("GET", f"/forecast_points/{testid}")
    assert {"TDryBul", "relHum", "HGloHor", "PriceElectricPowerConstant", "PriceElectricPowerDynamic"} <= set(f)
    assert f["TDryBul"]["Unit"] == "K"
    assert c.ok("GET", f"/step/{testid}") == 600
    assert c.ok("GET", f"/scenario/{testid}") == {"electricity_price": "constant", "time_period": None,
                                                  "temperature_uncertainty": None, "solar_uncertainty": None,
                                                  "seed": None}  # fmt: skip
    c.stop(testid)
    status, answer = c.request("GET", f"/status/{testid}")
    assert status == 404 and "was stopped (PUT /stop)" in answer["message"], answer


def test_a_test_steps_energyplus_with_and_without_the_inputs(server):
    """initialize, step, advance with and without activation, saturation, results, forecast, scenario, kpi."""
    port, proc, _ = server
    c = Boptest(port)
    testid = c.select(weather="IL")
    state = c.initialize(testid, START + 60, 3600)  # rounded up to the model's 10-minute timestep
    assert state["time"] == START + 600
    assert state["heating_setpoint_activate"] == 0
    assert state["heating_setpoint_u"] == pytest.approx(15.6 + 273.15)  # the building's own (setback) schedule
    assert 280 < state["core_temp_y"] < 300  # K
    assert len(energyplus_of(proc.pid)) == 1
    assert c.ok("PUT", f"/step/{testid}", {"step": 1200}) == {"step": 1200}

    own = c.advance(testid)  # no input: the building's own controls
    assert own["time"] == START + 600 + 1200
    assert own["heating_setpoint_activate"] == 0 and own["hvac_naturalgas_y"] < 1.0  # night setback: no heating
    status, answer = c.request("POST", f"/advance/{testid}", {"heating_setpoint_u": 295.15,
                                                             "heating_setpoint_activate": 1,
                                                             "cooling_setpoint_u": 297.15,
                                                             "cooling_setpoint_activate": 1})  # fmt: skip
    assert status == 200 and answer["message"].startswith("Advanced simulation successfully"), answer
    on = answer["payload"]
    assert on["heating_setpoint_u"] == 295.15 and on["heating_setpoint_activate"] == 1
    assert on["hvac_naturalgas_y"] > 1000.0  # 22 °C asked at night: the furnaces run
    status, answer = c.request("POST", f"/advance/{testid}", {"heating_setpoint_u": 400,
                                                             "heating_setpoint_activate": 1})  # fmt: skip
    assert status == 200 and "saturated to 295.15" in answer["message"], answer
    assert answer["payload"]["heating_setpoint_u"] == pytest.approx(295.15)
    assert answer["payload"]["cooling_setpoint_activate"] == 0
    back = c.advance(testid, {"heating_setpoint_u": 295.15, "heating_setpoint_activate": 0})  # a value not activated
    assert back["heating_setpoint_u"] == pytest.approx(15.6 + 273.15) and back["heating_setpoint_activate"] == 0

    r = c.ok("PUT", f"/results/{testid}", {"point_names": ["heating_setpoint_u", "core_temp_y"],
                                           "start_time": START + 600, "final_time": back["time"]})  # fmt: skip
    assert r["time"] == [START + 600 * k for k in range(1, 10)]  # every timestep, the start's state included
    assert r["heating_setpoint_u"][3:7] == pytest.approx([295.15] * 4)
    assert r["heating_setpoint_u"][-1] == pytest.approx(288.75)

    f = c.ok("PUT", f"/forecast/{testid}", {"point_names": ["TDryBul", "PriceElectricPowerDynamic"],
                                            "horizon": 3600, "interval": 900})  # fmt: skip
    assert f["time"] == [back["time"] + 900 * k for k in range(5)]
    assert f["TDryBul"][0] == pytest.approx(back["outdoor_temp_y"], abs=0.5)
    assert f["PriceElectricPowerDynamic"] == [0.05871] * 5  # winter off-peak

    k = c.ok("GET", f"/kpi/{testid}")
    assert set(k) == {"tdis_tot", "idis_tot", "ener_tot", "cost_tot", "emis_tot", "pele_tot", "pgas_tot",
                      "pdih_tot", "time_rat"}  # fmt: skip
    assert k["idis_tot"] is None and k["pdih_tot"] is None  # no CO2, no district heating in this model
    assert k["ener_tot"] > 0 and k["pgas_tot"] > 0 and k["cost_tot"] > 0 and k["emis_tot"] > 0
    assert k["time_rat"] >= 0

    changed = c.ok("PUT", f"/scenario/{testid}", {"electricity_price": "dynamic", "temperature_uncertainty": "high",
                                                  "seed": 5})  # fmt: skip
    assert changed["electricity_price"] == "dynamic" and changed["temperature_uncertainty"] == "high"
    errored = c.ok("PUT", f"/forecast/{testid}", {"point_names": ["TDryBul"], "horizon": 3600, "interval": 900})
    assert errored["TDryBul"] != f["TDryBul"]  # BOPTEST's forecast error
    assert c.ok("GET", f"/kpi/{testid}")["ener_tot"] == 0  # KPIs start afresh with a scenario, as BOPTEST's do
    c.stop(testid)
    assert energyplus_of(proc.pid) == []


def test_a_time_period_scenario_starts_the_test_period_after_its_warmup(server):
    port, _, _ = server
    c = Boptest(port)
    testid = c.select(weather="IL")
    answer = c.ok("PUT", f"/scenario/{testid}", {"time_period": "peak_heat_day"})
    assert answer["time_period"]["time"] == 19 * DAY  # the scored period's first day, after the warm-up day
    assert c.ok("GET", f"/scenario/{testid}")["time_period"] == "peak_heat_day"
    assert c.advance(testid)["time"] == 19 * DAY + 600
    c.stop(testid)


def test_tests_run_concurrently_and_queue_beyond_the_workers(server):
    port, proc, _ = server
    c = Boptest(port)
    first, second, third = c.select(weather="IL"), c.select(weather="IL"), c.select(weather="IL")
    assert [c.ok("GET", f"/status/{t}") for t in (first, second, third)] == ["Running", "Running", "Queued"]
    assert "cooling_setpoint_u" in c.ok("GET", f"/inputs/{third}")  # a queued test's metadata at once
    times, errors = {}, []

    def run(testid, start):
        try:
            own = Boptest(port)
            own.initialize(testid, start, 0)
            for _ in range(6):
                times[testid] = own.advance(testid, {"cooling_setpoint_u": 300, "cooling_setpoint_activate": 1})["time"]
        except Exception as e:  # noqa: BLE001 - reported below
            errors.append(e)

    threads = [threading.Thread(target=run, args=(t, START + i * DAY)) for i, t in enumerate((first, second))]
    for t in threads:
        t.start()
    for t in threads:
        t.join(timeout=300)
    assert errors == [] and times == {first: START + 3600, second: START + DAY + 3600}
    assert len(energyplus_of(proc.pid)) == 2
    c.stop(first)
    assert c.ok("GET", f"/status/{third}") == "Running"
    for t in (second, third):
        c.stop(t)
    assert energyplus_of(proc.pid) == []


def test_an_idle_test_is_stopped_and_its_process_is_gone(server):
    port, proc, _ = server
    c = Boptest(port)
    testid = c.select(weather="IL")
    c.initialize(testid, START, 0)
    assert len(energyplus_of(proc.pid)) == 1
    time.sleep(IDLE_S + 3)
    status, answer = c.request("POST", f"/advance/{testid}", {})
    assert status == 404 and f"after {IDLE_S:g} s without a request" in answer["message"], answer
    assert energyplus_of(proc.pid) == []


def test_a_killed_energyplus_fails_its_test_and_leaves_nothing(server):
    port, proc, _ = server
    c = Boptest(port)
    testid = c.select(weather="IL")
    c.initialize(testid, START, 0)
    (pid,) = energyplus_of(proc.pid)
    os.kill(pid, signal.SIGKILL)
    status, answer = c.request("POST", f"/advance/{testid}", {})
    assert status == 500 and "Failed to advance simulation" in answer["message"], answer
    assert answer["payload"] is None
    assert energyplus_of(proc.pid) == []
    c.stop(testid)


def test_bad_input_is_a_4xx_naming_the_problem(server):
    port, _, _ = server
    c = Boptest(port)

    def refused(method, path, body=None, raw=None, status=400):
        got, answer = c.request(method, path, body, raw)
        assert got == status and answer["status"] == status and answer["payload"] is None, answer
        return answer["message"]

    assert "office-small" in refused("POST", "/testcases/nowhere/select", {}, status=404)
    assert "weather 'Atlantis'" in refused("POST", f"/testcases/{TESTCASE}/select", {"weather": "Atlantis"})
    assert "['colour']" in refused("POST", f"/testcases/{TESTCASE}/select", {"colour": "red"})
    testid = c.select(weather="IL")
    assert "not valid JSON" in refused("POST", f"/advance/{testid}", raw=b"{not json")
    assert "Unexpected input variable: fan_u" in refused("POST", f"/advance/{testid}", {"fan_u": 1})
    assert "an activation is 1" in refused("POST", f"/advance/{testid}", {"cooling_setpoint_activate": 2})
    assert "cooling_setpoint_u is not given" in refused("POST", f"/advance/{testid}", {"cooling_setpoint_activate": 1})
    assert "must be a number" in refused("POST", f"/advance/{testid}", {"cooling_setpoint_u": "warm",
                                                                        "cooling_setpoint_activate": 1})  # fmt: skip
    assert "lacks warmup_period" in refused("PUT", f"/initialize/{testid}", {"start_time": 0})
    assert "must not be negative" in refused("PUT", f"/initialize/{testid}", {"start_time": -5, "warmup_period": 0})
    assert "multiple of the model's timestep, 600 s" in refused("PUT", f"/step/{testid}", {"step": 900})
    assert "['nope_y']" in refused("PUT", f"/results/{testid}", {"point_names": ["nope_y"], "start_time": 0,
                                                                 "final_time": 1})  # fmt: skip
    assert "['core_temp_y']" in refused("PUT", f"/forecast/{testid}", {"point_names": ["core_temp_y"],
                                                                       "horizon": 0, "interval": 60})  # fmt: skip
    assert "interval" in refused("PUT", f"/forecast/{testid}", {"point_names": ["TDryBul"], "horizon": 60,
                                                                "interval": 0})  # fmt: skip
    assert "'cheap'" in refused("PUT", f"/scenario/{testid}", {"electricity_price": "cheap"})
    assert "no highly dynamic price series" in refused("PUT", f"/scenario/{testid}",
                                                       {"electricity_price": "highly_dynamic"})  # fmt: skip
    assert "time_period is 'summer'" in refused("PUT", f"/scenario/{testid}", {"time_period": "summer"})
    assert "non-negative integer" in refused("PUT", f"/scenario/{testid}", {"seed": -1})
    assert c.ok("GET", f"/scenario/{testid}")["electricity_price"] == "constant"  # nothing refused was applied
    c.stop(testid)
    assert "was stopped" in refused("POST", f"/advance/{testid}", {}, status=404)
    assert "no test nonsense" in refused("GET", "/kpi/nonsense", status=404)


def test_the_command_refuses_what_would_expose_or_misconfigure_it(tmp_path):
    off = cli("boptest", "--host", "0.0.0.0", "--port", str(free_port()), timeout_s=60)
    assert off.returncode != 0 and "--token-file" in off.stderr
    assert "no .toml building spec" in cli("boptest", "--specs", str(tmp_path), timeout_s=60).stderr
    assert "--workers 0" in cli("boptest", "--workers", "0", "--port", str(free_port()), timeout_s=60).stderr


def test_a_spec_folder_adds_its_test_cases(tmp_path):
    from parallel_eplus.buildings.resources import builtin_specs
    from parallel_eplus.deploy.boptest.registry import Registry, testcases_of
    from parallel_eplus.deploy.boptest.test import TestError

    (tmp_path / "my-office.toml").write_text(Path(builtin_specs()["office-small"]).read_text())
    cases = testcases_of(tmp_path)
    assert cases["my-office"] == (tmp_path / "my-office.toml").resolve() and "office-medium" in cases
    (tmp_path / "broken.toml").write_text('name = "broken"\nidf = "nowhere.idf"\n')
    registry = Registry(testcases_of(tmp_path), workers=1)
    try:
        with pytest.raises(TestError) as refused:
            registry.select("broken", {})
        assert refused.value.status == 500 and "test case 'broken': its spec" in refused.value.message
    finally:
        registry.close()


def test_a_tests_kpis_are_evaluates_for_the_same_controller_and_period(tmp_path):
    """A day of the building's own controls (no input activated) through a test, in process, against `evaluate`'s
    baseline on the same day: BOPTEST's KPIs equal the summary's figures (cost aside: the test's price scenario is
    BOPTEST's constant price, the evaluation's the spec's tariff)."""
    from parallel_eplus.deploy.boptest.test import BoptestTest
    from parallel_eplus.evaluation.controllers import BASELINE_LABEL, Controller
    from parallel_eplus.evaluation.sweep import run_sweep

    test = BoptestTest(TESTCASE, TESTCASE, "IL")
    try:
        test.initialize(0, 0, end_time=DAY)
        steps = 0
        while test.advance({})[1]:
            steps += 1
            if steps % 50 == 0:  # the running totals part way; the rest folded in after the episode's end
                same_kpis(test.kpi()[1], test.kpi_recomputed())
        kpi = test.kpi()[1]
        same_kpis(kpi, test.kpi_recomputed())
    finally:
        test.close()
    row = run_sweep([Controller(BASELINE_LABEL, "baseline")], ["IL"], 1, 1, tmp_path, progress=False,
                    building=TESTCASE).iloc[0]  # fmt: skip
    assert steps == row["steps"] == 144
    assert kpi["tdis_tot"] == pytest.approx(row["discomfort_kh"], rel=1e-9) and kpi["tdis_tot"] > 0
    assert kpi["ener_tot"] == pytest.approx(row["hvac_energy_kwh_m2"], rel=1e-9)
    assert kpi["emis_tot"] == pytest.approx(row["emissions_kg_m2"], rel=1e-9)
    assert kpi["pele_tot"] == pytest.approx(row["hvac_electricity_peak_kw_m2"], rel=1e-9)
    assert kpi["pgas_tot"] == pytest.approx(row["hvac_naturalgas_peak_kw_m2"], rel=1e-9)


def same_kpis(incremental: dict, recomputed: dict) -> None:
    """`/kpi`'s running totals against the recomputation over every step: the same figures, to float rounding."""
    assert set(incremental) == set(recomputed)
    for key, value in recomputed.items():
        if value is None:
            assert incremental[key] is None, key
        else:
            assert incremental[key] == pytest.approx(value, rel=1e-9, abs=1e-12), key


def test_kpis_kept_as_running_totals_equal_a_recomputation_over_every_step():
    """`/kpi` folds in only the steps new since the last request: after each of several advances (the heating
    setpoint overwritten on some, so gas and electricity both run), and after a price scenario starts the KPIs
    afresh, they equal the KPIs recomputed over every scored step at once."""
    from parallel_eplus.deploy.boptest.test import BoptestTest

    test = BoptestTest(TESTCASE, TESTCASE, "IL")
    try:
        test.initialize(START, 3600)
        test.set_step(1200)
        heat = {"heating_setpoint_u": 295.15, "heating_setpoint_activate": 1}
        for k in range(12):
            test.advance(heat if k % 3 else {})
            if k in (0, 1, 4, 11):
                kpi = test.kpi()[1]
                same_kpis(kpi, test.kpi_recomputed())
        assert kpi["pgas_tot"] > 0 and kpi["pele_tot"] > 0 and kpi["cost_tot"] > 0 and kpi["time_rat"] >= 0
        constant = kpi["cost_tot"] / kpi["ener_tot"]
        test.set_scenario({"electricity_price": "dynamic"})
        assert test.kpi()[1]["ener_tot"] == 0 == test.kpi_recomputed()["ener_tot"]
        for k in range(6):
            test.advance(heat if k % 2 else {})
            if k in (2, 5):
                kpi = test.kpi()[1]
                same_kpis(kpi, test.kpi_recomputed())
        assert kpi["ener_tot"] > 0 and kpi["cost_tot"] / kpi["ener_tot"] != pytest.approx(constant)
    finally:
        test.close()
