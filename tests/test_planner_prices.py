"""The planner's objective: under a time-of-use tariff its horizon is priced step by step (energy_weights.py), as
the reward prices it, and an exported planner prices it the same from its contract's tariff."""

from __future__ import annotations

import datetime as dt
import json
import shutil
import tomllib
from pathlib import Path

import numpy as np
import pytest
import torch as th

from parallel_eplus.buildings.resources import model_file, spec_file, tariff_file
from parallel_eplus.buildings.tariff import Tariff
from parallel_eplus.deploy.contract import Contract
from parallel_eplus.deploy.export import export
from parallel_eplus.deploy.planner_runtime import PlannerRuntime
from parallel_eplus.learning.model_based.control import MPC
from parallel_eplus.learning.model_based.dataset import Layout
from parallel_eplus.learning.model_based.energy_weights import EnergyWeights

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
    emissions = EnergyWeights.of(LAYOUT, "emissions", {"hvac_power_w": "NaturalGas"}, {}, {"Electricity": 0.4,
                                                                                             "NaturalGas": 0.2})
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
