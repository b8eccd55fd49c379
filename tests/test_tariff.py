"""Prices and peaks: time-of-use periods, demand charges, the monthly bill and the cost objective's per-step share of
the demand charges (pricing/tariff.py, bill.py), on a real episode of the small office across a month's end."""

from __future__ import annotations

import datetime as dt
import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from parallel_eplus.buildings.pricing.tariff import price_outlook
from parallel_eplus.buildings.spec.load import SpecError, load_spec

from .test_kpis import office_spec

EXAMPLE = """[kpis]
hvac = { Electricity = "hvac_power_w", NaturalGas = "NaturalGas:HVAC" }
tariff = { Electricity = { file = "commercial-tou-demand.toml" }, NaturalGas = 0.04 }
"""


def winter_price(start: pd.Timestamp) -> float:
    """The example tariff's winter energy price, written out (tariffs/commercial-tou-demand.toml)."""
    hour = start.hour + start.minute / 60
    if 14 <= hour < 19:
        return 0.15990
    return 0.06906 if 6 <= hour < 14 or 19 <= hour < 22 else 0.05871


def test_the_example_tariff_prices_any_future_step(tmp_path):
    spec = load_spec(office_spec(tmp_path, EXAMPLE))
    starts = [dt.datetime(2013, 7, 2, 15), dt.datetime(2013, 7, 6, 15), dt.datetime(2013, 1, 2, 3)]  # Tue, Sat, Wed
    out = price_outlook(spec, starts)
    assert list(out.price) == [0.16969, 0.16969, 0.05871]  # summer super peak every day; winter night
    assert list(out.demand_rate) == pytest.approx([11.98 + 16.37, 11.98, 11.98])  # on-peak demand on weekdays only
    assert list(out.on_peak) == [True, False, False]
    assert list(price_outlook(spec, starts, "NaturalGas").price) == [0.04] * 3


def test_tariff_mistakes_are_named(tmp_path):
    bad = EXAMPLE.replace(
        '{ file = "commercial-tou-demand.toml" }, NaturalGas = 0.04',
        '{ price = 0.1, csv = "p.csv", demand = [{ price = 5, hours = [8, 25], weekdays = ["Mo"] }] }, '
        'NaturalGas = { price = 0.04, demand = [{ price = 1 }] }, Propane = { file = "nowhere.toml" }',
    )
    with pytest.raises(SpecError) as e:
        load_spec(office_spec(tmp_path, bad))
    message = str(e.value)
    for expected in ("kpis.tariff.Electricity: give the energy price once", "demand[0].hours: [8, 25]",
                     "demand[0].weekdays: ['Mo']", "kpis.tariff.NaturalGas.demand: demand charges apply to Electricity",
                     "kpis.tariff.Propane.file: tariff file 'nowhere.toml' not found"):  # fmt: skip
        assert expected in message, message


@pytest.mark.slow
def test_bill_and_demand_surrogate_against_a_hand_computation(tmp_path, no_leaks):
    """January 31 and February 1 under the example tariff, `--objective cost`: each month's energy and demand
    charges as computed here by hand from the step table (15-minute means by resampling), and the reward's per-step
    demand charges summing to the bill's."""
    from parallel_eplus.engine.config import SimulationConfig
    from parallel_eplus.engine.simulation import Simulation

    spec = office_spec(tmp_path, EXAMPLE)
    cfg = SimulationConfig(weather="CA", building=str(spec), run_days=2, start_day=31, start_weekday="Sunday",
                           objective="cost", output_dir=str(tmp_path / "run"))  # fmt: skip
    sim = Simulation(cfg)
    charged, power_terms = [], []
    try:
        sim.start()
        done = False
        while not done:
            sim.send(np.array([1.0, -1.0]))  # cooling 30, heating 15: a quiet building, its peaks its own
            _, _, done, info = sim.receive()
            charged.append(info["demand_charge"])
            power_terms.append((info["reward_power"], info["hvac_power_w"], info["hvac_naturalgas_w"], info["time"]))
    finally:
        sim.close()
    summary = info["episode_summary"]
    steps = pd.read_parquet(Path(info["episode_dir"]) / "steps.parquet")
    start = steps["time"] - pd.Timedelta(minutes=10)
    assert set(start.dt.month) == {1, 2}
    # a weekend day in January (no on-peak demand charge), a weekday in February
    assert (start.iloc[0].day_name(), start.iloc[-1].day_name()) == ("Sunday", "Monday")

    kwh = steps["power_w"] * 10 / 60 / 1000  # the facility's meter: lights and plugs too
    energy = (kwh * start.map(winter_price)).groupby(start.dt.month).sum()
    pieces = pd.Series(np.repeat(steps["power_w"].to_numpy() / 1000, 2),
                       index=np.ravel([start, start + pd.Timedelta(minutes=5)], order="F"))  # fmt: skip
    quarters = pieces.resample("15min").agg(["mean", "count"])
    quarters = quarters[quarters["count"] == 3]["mean"]  # whole quarter hours
    on = (quarters.index.day_of_week < 5) & (quarters.index.hour >= 8) & (quarters.index.hour < 21)
    for month in (1, 2):
        q = quarters[quarters.index.month == month]
        weekday = q[on[quarters.index.month == month]]
        demand = 11.98 * q.max() + (0.23 * weekday.max() if len(weekday) else 0.0)  # no weekday: no on-peak charge
        assert summary[f"bill_energy_{month:02d}"] == pytest.approx(energy[month], rel=1e-9)
        assert summary[f"bill_demand_{month:02d}"] == pytest.approx(demand, rel=1e-9)
        assert summary[f"peak_15min_kw_{month:02d}"] == pytest.approx(q.max())
    assert summary["bill"] == pytest.approx(energy.sum() + summary["bill_demand"])
    assert summary["bill_demand"] > 0.5 * summary["bill"]  # two days: the month's demand charges dominate

    assert sum(charged) == pytest.approx(summary["bill_demand"], rel=1e-9)  # the surrogate sums to the bill's
    assert sum(c > 0 for c in charged) < len(charged) / 4  # paid when a peak rises, not every step
    k = int(np.argmax(charged))
    reward_power, hvac, gas, time = power_terms[k]
    mean = 0.0854791  # the example's mean energy price over a year's hours
    priced = (hvac * winter_price(pd.Timestamp(time) - pd.Timedelta(minutes=10)) + gas * 0.04) / mean
    demand_w = charged[k] / (mean * 10 / 60 / 1000)
    assert reward_power == pytest.approx(-cfg.reward.power_weight * (priced + demand_w), rel=1e-5)
    json.dumps(summary)  # the bill's figures are plain numbers
