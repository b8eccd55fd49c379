"""The shipped specs name variables and actuators their models have, and the actuators take effect.

A short run through the EnergyPlus API (one simulated day after warm-up, no env, no pipes, on the copy of the
model the engine prepares), so these hold before the spec is wired through the engine and stay cheap after.
"""

from __future__ import annotations

import math
import tempfile
from pathlib import Path

import pytest

from parallel_eplus.buildings import resources
from parallel_eplus.buildings.idf.prepare import prepare_idf
from parallel_eplus.buildings.spec.load import BuildingSpec, load_spec
from parallel_eplus.buildings.starter.survey import RUN_PERIOD_WEATHER

SPECS = sorted(resources.spec_dir().glob("*.toml"))


def run_day(spec: BuildingSpec, actions: dict[str, float] | None = None, idf: Path | None = None) -> dict:
    """Hold each action at `actions` (default: its initial value) for a day; every observation's samples."""
    from pyenergyplus.api import EnergyPlusAPI

    api = EnergyPlusAPI()
    state = api.state_manager.new_state()
    api.runtime.set_console_output_status(state, False)
    for o in spec.observations:
        if o.meter is None:
            api.exchange.request_variable(state, o.variable, o.key)
    values = {a.name: (actions or {}).get(a.name, a.initial) for a in spec.actions}
    handles: dict = {}
    samples: dict[str, list[float]] = {o.name: [] for o in spec.observations}

    def before_hvac(s) -> None:
        if not api.exchange.api_data_fully_ready(s):
            return
        if not handles:
            x = api.exchange
            handles["obs"] = {
                o.name: x.get_meter_handle(s, o.meter) if o.meter else x.get_variable_handle(s, o.variable, o.key)
                for o in spec.observations
            }
            handles["act"] = [
                (a.name, x, api.exchange.get_actuator_handle(s, x.component, x.control, x.key))
                for a in spec.actions
                for x in a.actuators
            ]
            if -1 in handles["obs"].values() or any(h == -1 for *_, h in handles["act"]):
                api.runtime.stop_simulation(s)
                return
        for name, _, h in handles["act"]:
            api.exchange.set_actuator_value(s, h, values[name])

    def after_zone(s) -> None:
        if not handles or api.exchange.warmup_flag(s) or -1 in handles["obs"].values():
            return
        if api.exchange.kind_of_sim(s) != RUN_PERIOD_WEATHER:  # sizing's design days (the office runs two first)
            return
        step_s = 3600 / api.exchange.num_time_steps_in_hour(s)
        for o in spec.observations:  # a meter as its mean rate over the step (J -> W), as the engine reads it
            h = handles["obs"][o.name]
            value = api.exchange.get_meter_value(s, h) / step_s if o.meter else api.exchange.get_variable_value(s, h)
            samples[o.name].append(value * o.scale)
        if len(samples[spec.observations[0].name]) >= 24 * api.exchange.num_time_steps_in_hour(s):
            api.runtime.stop_simulation(s)

    api.runtime.callback_after_predictor_after_hvac_managers(state, before_hvac)
    api.runtime.callback_end_zone_timestep_after_zone_reporting(state, after_zone)
    with tempfile.TemporaryDirectory(prefix="eplus-spec-check-") as out:
        weather = next(iter(spec.weathers.values()))
        model = Path(out) / "model.idf"
        prepare_idf(idf or spec.idf, model, run_days=2)
        api.runtime.run_energyplus(state, ["-d", out, "-w", str(weather), str(model)])
    api.state_manager.delete_state(state)
    missing = [f"observation {n}" for n, h in handles.get("obs", {}).items() if h == -1]
    missing += [f"{n}: {x.component}/{x.control}/{x.key}" for n, x, h in handles.get("act", []) if h == -1]
    assert handles and not missing, f"{spec.path.name}: not in the model: {missing}"
    return samples


@pytest.mark.slow
@pytest.mark.parametrize("path", SPECS, ids=[p.stem for p in SPECS])
def test_spec_resolves_and_holds_its_initial_action(path):
    spec = load_spec(path)
    samples = run_day(spec)
    for o in spec.observations:
        assert samples[o.name] and all(math.isfinite(v) and o.low <= v <= o.high for v in samples[o.name]), o.name
    assert min(samples[spec.reward.power]) > 0


def mean(xs: list[float]) -> float:
    return sum(xs) / len(xs)


@pytest.mark.slow
def test_crac_agent_owns_supply_temperature_and_fan():
    """With the Warmest manager disabled the supply setpoint reaches the servers' inlet (supply + 2 K approach)."""
    spec = load_spec(resources.spec_dir() / "datacenter-crac.toml")
    cool = run_day(spec, {"supply_temp_c": 18.0, "fan_kg_s": 10.0})
    warm = run_day(spec, {"supply_temp_c": 24.0, "fan_kg_s": 10.0})
    assert mean(cool["it_inlet_c"]) == pytest.approx(20.0, abs=0.3)
    assert mean(warm["it_inlet_c"]) == pytest.approx(26.0, abs=0.3)
    # The stock model's own manager overrides the same actuator: the reason for the agent copy.
    stock = run_day(spec, {"supply_temp_c": 18.0, "fan_kg_s": 10.0}, idf=spec.baseline_idf)
    assert mean(stock["it_inlet_c"]) > 21.0


@pytest.mark.slow
def test_office_setpoints_move_the_zones():
    spec = load_spec(resources.spec_dir() / "office-small.toml")
    cool = run_day(spec, {"cooling_setpoint_c": 23.0, "heating_setpoint_c": 22.0})
    warm = run_day(spec, {"cooling_setpoint_c": 30.0, "heating_setpoint_c": 15.0})
    for zone in spec.reward.temperatures:  # a January day: heating at 22 C holds the zones near it
        assert 21.0 < mean(cool[zone]) < 23.0 and mean(warm[zone]) < mean(cool[zone]) - 1.0, zone
    assert mean(warm["hvac_power_w"]) < mean(cool["hvac_power_w"]) / 2
