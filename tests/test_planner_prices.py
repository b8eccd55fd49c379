"""The planner's objective: under a time-of-use tariff its horizon is priced step by step (energy_weights.py), and
its demand charges against the month's running peaks (demand.py), as the reward prices them, and an exported planner
prices them the same from its contract's tariff and the request's peaks."""

from __future__ import annotations

import datetime as dt
import json
import shutil
import tomllib
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import torch as th

from parallel_eplus.buildings.building import load_building
from parallel_eplus.buildings.pricing.bill import DemandTracker
from parallel_eplus.buildings.pricing.tariff import Tariff
from parallel_eplus.buildings.resources import model_file, spec_file, tariff_file
from parallel_eplus.deploy.export.policy import export
from parallel_eplus.deploy.serve.contract import Contract, InputError
from parallel_eplus.deploy.serve.planner_runtime import PlannerRuntime
from parallel_eplus.evaluation.controllers import http_controller
from parallel_eplus.evaluation.sweep import run_sweep
from parallel_eplus.learning.model_based.control.mpc import MPC
from parallel_eplus.learning.model_based.control.saved_planner import planner_controller
from parallel_eplus.learning.model_based.runtime.demand import DemandOutlook
from parallel_eplus.learning.model_based.runtime.energy_weights import EnergyWeights
from parallel_eplus.learning.model_based.runtime.layout import Layout
from parallel_eplus.learning.model_based.runtime.planner import PlanRequest

from .serving import serving

ROOT = Path(__file__).resolve().parents[1]
PLANNER = ROOT / "results/model-based/datacenter-2zone/runs/datacenter-2zone-mpc-seed0/best/planner"
TOU = tomllib.loads(tariff_file("commercial-tou-demand.toml").read_text())
SUMMER_PEAK, SUMMER_NIGHT, WINTER_NIGHT = 0.16969, 0.05826, 0.05871  # the example tariff's prices, written out
LAYOUT = Layout(("outdoor_temp_c", "west_temp_c", "east_temp_c", "power_w", "it_power_w", "hvac_power_w"),
                ("west_temp_c", "east_temp_c"), ("power_w",), 4, 6, ("hvac_power_w",))  # fmt: skip
STARTS = [dt.datetime(2013, 7, 9, 15), dt.datetime(2013, 7, 9, 3), dt.datetime(2013, 1, 8, 3)]


def test_each_objective_weighs_the_predicted_parts_as_the_reward_does():
    tou = Tariff.of(TOU, Path("."))
    mean = tou.mean_price()
    weights = EnergyWeights.of(LAYOUT, "cost", {"hvac_power_w": "Electricity"}, {"Electricity": tou}, {})
    expected = [[0, SUMMER_PEAK / mean], [0, SUMMER_NIGHT / mean], [0, WINTER_NIGHT / mean]]  # IT power unpriced
    assert weights.at(STARTS) == pytest.approx(np.array(expected, np.float32))
    hvac = EnergyWeights.of(LAYOUT, "hvac", {"hvac_power_w": "Electricity"}, {}, {})
    assert hvac.at(STARTS[:1]).tolist() == [[0.0, 1.0]]
    emissions = EnergyWeights.of(
        LAYOUT, "emissions", {"hvac_power_w": "NaturalGas"}, {}, {"Electricity": 0.4, "NaturalGas": 0.2}
    )
    assert emissions.at(STARTS[:1]).tolist() == [[0.0, 0.5]]
    assert EnergyWeights.of(LAYOUT, "energy", {}, {}, {}).at(STARTS[:1]).tolist() == [[1.0, 1.0]]
    no_parts = Layout(LAYOUT.sensors, LAYOUT.temperatures, ("power_w",), 4, 6)  # an unobserved HVAC meter
    priced = EnergyWeights.of(no_parts, "cost", {"x": "Electricity"}, {"Electricity": tou}, {})
    assert priced.at(STARTS[:1])[0, 0] == pytest.approx(SUMMER_PEAK / mean)  # every term at electricity's price
    with pytest.raises(ValueError, match="objective 'bill'"):
        EnergyWeights.of(LAYOUT, "bill", {}, {}, {})


@pytest.fixture(scope="module")
def priced_planner(tmp_path_factory) -> Path:
    """The committed data-center planner, its building under the example tariff and its objective the cost."""
    tmp = tmp_path_factory.mktemp("priced")
    spec = tmp / "datacenter-tou.toml"
    text = spec_file("datacenter-2zone").read_text()
    for idf in ("2ZoneDataCenterHVAC_wEconomizer_agent.idf", "2ZoneDataCenterHVAC_wEconomizer.idf"):
        text = text.replace(f'"{idf}"', f'"{model_file(idf)}"')
    spec.write_text(text + 'tariff = { Electricity = { file = "commercial-tou-demand.toml" } }\n')
    folder = tmp / "run" / "planner"
    shutil.copytree(PLANNER, folder)
    state = th.load(folder / "planner.pt", weights_only=True)
    th.save(state | {"building": str(spec), "objective": "cost"}, folder / "planner.pt")
    config = json.loads((folder / "config.json").read_text())
    (folder / "config.json").write_text(json.dumps(config | {"building": str(spec)}))
    return folder


def test_a_planner_under_a_tariff_prices_its_horizon_in_process_and_served(priced_planner, tmp_path, no_leaks):
    mpc = MPC.load(priced_planner / "planner.pt")
    mean = Tariff.of(TOU, Path(".")).mean_price()
    assert mpc.energy_weights.at(STARTS) == pytest.approx(
        np.array([[0, SUMMER_PEAK / mean], [0, SUMMER_NIGHT / mean], [0, WINTER_NIGHT / mean]], np.float32)
    )
    # The plan's cost counts the prices: the same decision at the summer peak costs more than at night.
    obs = np.zeros((1, 26), np.float32)
    obs[0, :6] = [18.0, 23.5, 23.5, 95000.0, 70000.0, 25000.0]
    costs = []
    for when in STARTS[:2]:
        mpc.reset(0)
        mpc.act(obs, [{"time": when, "weather": "CA"}], mpc.initial[None])
        costs.append(float(mpc.last.cost[0]))
    assert costs[0] > 1.5 * costs[1]
    # Exported: the contract carries the objective and the tariff, and the served plans equal the in-process ones
    # (export refuses any difference over its sampled decisions).
    out = tmp_path / "served"
    export(priced_planner.parent, out, record_days=1)
    contract = Contract.read(out)
    assert contract.data["planner"]["energy"]["objective"] == "cost"
    runtime = PlannerRuntime(out, contract)
    assert runtime.energy.at(STARTS) == pytest.approx(mpc.energy_weights.at(STARTS))


OFFICE = ROOT / "results/model-based/office-small/runs/office-small-mpc-seed0/planner"


def _office_under_cost() -> MPC:
    """The committed office planner, its objective the bill (the office's spec has the example tariff)."""
    return MPC.from_state(th.load(OFFICE / "planner.pt", weights_only=True) | {"objective": "cost"})


def test_the_planner_s_demand_charges_are_the_tariff_s_windows_over_the_month_s_running_peaks():
    mpc = _office_under_cost()
    d = mpc.demand.charges
    assert d.names == ["maximum", "summer peak", "summer part peak", "winter part peak"]
    assert mpc.layout.state_names[len(mpc.layout.temperatures) + d.part] == "power_w"  # the facility's meter
    kpis = load_building("office-small").comfort.kpis
    assert d.per_dollar == pytest.approx(kpis.demand_w(1.0, mpc.step_minutes))  # as the reward's surrogate weighs
    tuesday = dt.datetime(2013, 7, 9)
    starts = [tuesday.replace(hour=17, minute=50), tuesday.replace(hour=18), tuesday.replace(hour=21),
              dt.datetime(2013, 8, 1)]  # fmt: skip
    prices, running = d.outlook(starts, {(0, 2013, 7): 30.0, (1, 2013, 7): 25.0})
    # E-20's windows written out: summer peak weekdays 12-18 h, part peak 8-12 and 18-21 h, maximum any time
    np.testing.assert_allclose(prices, [[11.98, 16.37, 0, 0], [11.98, 0, 3.56, 0], [11.98, 0, 0, 0], [11.98, 0, 0, 0]])
    np.testing.assert_allclose(running, [[30, 25, 0, 0], [30, 0, 0, 0], [30, 0, 0, 0], [0, 0, 0, 0]])  # August: new
    assert not MPC.from_state(th.load(OFFICE / "planner.pt", weights_only=True)).demand  # energy: not priced


def test_a_candidate_pays_each_charge_s_price_for_the_rise_above_the_month_s_peak():
    """One step's plan: the demand term is each charge's price x how far the members' mean predicted facility
    demand rises above the running peak, in the energy term's units; a peak already above it costs nothing."""
    mpc = _office_under_cost()
    d = mpc.demand.charges
    when = dt.datetime(2013, 7, 9, 15, 0)
    info = {"time": when, "weather": "CA"}
    exo, applies, bounds, _ = mpc.future([info])
    obs = np.array([[30.0, 23.5, 23.5, 23.5, 23.5, 23.5, 12000.0, 4000.0, 0.0, 1.0]], np.float32)
    s = mpc.layout.state(obs[:, : len(mpc.layout.sensors)])
    a_last = np.array([[-0.5, 0.8]], np.float32)
    actions = a_last[:, None, None, :]  # [W, N, H=1, A]
    parts = mpc.layout.n_state - len(mpc.layout.temperatures)
    zero, power = np.zeros((1, 1, parts), np.float32), np.zeros((1, 1, parts), np.float32)
    power[..., d.part] = 1.0

    def cost(weights, demand=None) -> float:
        seen = PlanRequest(s, a_last, exo[:, :1], 0 * applies[:, :1], bounds[:, :1], 0.0, mpc.support,
                           np.zeros((1, 1, 2), np.float32), [0], energy_weights=weights, demand=demand)  # fmt: skip
        return float(mpc.planner._cost(seen, actions)[0][0, 0])

    base = cost(zero)
    watts = (cost(power) - base) / mpc.power_weight  # the members' mean predicted facility demand
    assert 1000 < watts < 50000
    prices, running = d.outlook([when], {})
    paid = prices.sum() * d.per_dollar * mpc.power_weight  # per kW above every peak
    assert cost(zero, DemandOutlook(prices[None], running[None], d.part, d.per_dollar)) - base == pytest.approx(
        paid * watts / 1000, rel=1e-4
    )  # a month with no peak yet: all of it
    near = np.where(prices > 0, watts / 1000 - 2.0, 0.0).astype(np.float32)
    assert cost(zero, DemandOutlook(prices[None], near[None], d.part, d.per_dollar)) - base == pytest.approx(
        2 * paid, rel=1e-3
    )  # 2 kW above this month's peaks
    high = np.full_like(running, 1e6)
    assert cost(zero, DemandOutlook(prices[None], high[None], d.part, d.per_dollar)) == base


def test_the_planner_tracks_each_worker_s_peaks_from_its_readings_as_the_bill_does():
    mpc = _office_under_cost()
    column = mpc.layout.sensors.index("power_w")
    obs = np.array([[30.0, 23.5, 23.5, 23.5, 23.5, 23.5, 0.0, 4000.0, 0.0, 1.0]], np.float32)
    start = dt.datetime(2013, 7, 9, 13, 0)
    expected = DemandTracker(mpc.demand.charges.tariff, 10)
    for k, watts in enumerate([20000.0, 30000.0, 25000.0, 26000.0]):
        obs[0, column] = watts
        now = start + dt.timedelta(minutes=10 * k)
        mpc.act(obs, [{"time": now, "weather": "CA"}], np.zeros((1, 2), np.float32))
        mpc.act(obs, [{"time": now, "weather": "CA"}], np.zeros((1, 2), np.float32))  # asked again: fed once
        if k:  # an episode's first reading ends its warm-up, no step of its own
            expected.step(now - dt.timedelta(minutes=10), watts)
    assert mpc.demand.trackers[0].peaks == expected.peaks and expected.peaks[(0, 2013, 7)] == pytest.approx(85 / 3)
    mpc.reset(0)
    assert mpc.demand.trackers[0].peaks == {}


@pytest.fixture(scope="module")
def office_cost(tmp_path_factory) -> tuple[Path, Path]:
    """The office's cost planner as a run's planner folder, and its export (which refuses any served plan that
    differs from the in-process one over its sampled decisions)."""
    tmp = tmp_path_factory.mktemp("office-cost")
    folder = tmp / "run" / "planner"
    shutil.copytree(OFFICE, folder)
    state = th.load(folder / "planner.pt", weights_only=True)
    th.save(state | {"objective": "cost"}, folder / "planner.pt")
    export(folder.parent, tmp / "served", record_days=1)
    return folder, tmp / "served"


@pytest.mark.slow
def test_an_exported_planner_prices_demand_from_the_request_s_peaks(office_cost, no_leaks):
    contract = Contract.read(office_cost[1])
    assert contract.data["planner"]["demand"]["power"] == "power_w"
    assert contract.data["demand_peaks_kw"]["charges"][0] == "maximum"
    assert contract.data["export_check"]["decisions_with_demand_peaks"] > 24  # checked with peaks, not only without
    runtime = PlannerRuntime(office_cost[1], contract)
    body = {"time": "2013-07-09T15:00:00", "last_setpoints": {"cooling_setpoint_c": 24.0, "heating_setpoint_c": 21.0},
            "sensors": {"outdoor_temp_c": 30.0, "core_temp_c": 23.5, "perimeter_1_temp_c": 23.5,
                        "perimeter_2_temp_c": 23.5, "perimeter_3_temp_c": 23.5, "perimeter_4_temp_c": 23.5,
                        "power_w": 12000.0, "hvac_power_w": 4000.0, "gas_w": 0.0, "occupancy": 1.0},
            "forecast": {"outdoor_drybulb_c": [30.0] * 12, "outdoor_rh_pct": [40.0] * 12,
                         "global_horizontal_w_m2": [600.0] * 12}}  # fmt: skip
    fresh = runtime.act(body)
    peaked = runtime.act(body | {"demand_peaks_kw": {n: 1000.0 for n in contract.data["demand_peaks_kw"]["charges"]}})
    assert fresh["cost"] > peaked["cost"] + 100  # a month with no peak yet pays for every kW of the plan
    with pytest.raises(InputError, match="demand_peaks_kw.*no demand charge named"):
        runtime.act(body | {"demand_peaks_kw": {"peak": 10.0}})
    with pytest.raises(InputError, match=r"^demand_peaks_kw\.maximum: -1 is not a demand in kW"):
        runtime.act(body | {"demand_peaks_kw": {"maximum": -1}})
    with pytest.raises(InputError, match=r"^demand_peaks_kw\.maximum: .* is not a demand in kW"):
        runtime.act(body | {"demand_peaks_kw": {"maximum": 10**400}})
    with pytest.raises(InputError, match="^demand_peaks_kw: an object"):
        runtime.act(body | {"demand_peaks_kw": []})


@pytest.mark.slow
def test_a_served_cost_planner_in_closed_loop_keeps_the_month_s_peaks_as_the_in_process_one(office_cost, tmp_path,
                                                                                             no_leaks):  # fmt: skip
    """A day of the office through the server, its client keeping the month's peaks from the meter and sending
    them: every reading and setpoint equals the in-process planner's, whose trackers keep them itself."""
    with serving(office_cost[1], tmp_path / "server.log") as url:
        planner = planner_controller(f"{office_cost[0]}=Planner")
        df = run_sweep([planner, http_controller(url)], ["CA"], 1, 2, tmp_path / "eval", progress=False,
                       building="office-small")  # fmt: skip
    in_process, over_http = (pd.read_parquet(Path(d) / "steps.parquet") for d in df.episode_dir)
    assert len(in_process) == 144
    pd.testing.assert_frame_equal(in_process, over_http, check_exact=True)
