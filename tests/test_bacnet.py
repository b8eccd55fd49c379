"""BACnet in closed loop over loopback: `simulate --bacnet` (a real EnergyPlus episode as a BACnet/IP device) and
`serve --bacnet` (the exported controller as its supervisor), each its own process, talking BACnet/IP over UDP on
127.0.0.1 with a port each; the test's own BAC0 client stands in for an operator, a rogue client or a clock."""

from __future__ import annotations

import asyncio
import datetime as dt
import glob
import math
import signal
import time
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from parallel_eplus.deploy.bacnet.point_map import PointMap
from parallel_eplus.deploy.export.policy import export

from .bacnet_loop import HOST, Client, Loop

pytest.importorskip("BAC0")

ROOT = Path(__file__).resolve().parents[1]
MODEL = ROOT / "results" / "paper" / "models" / "paper-ca-co-fl-time"  # TRPO with time features, committed
# Where a test's device stops once the supervisor under test has left (step 10): its later steps would only repeat
# what the steps up to here show, the building under its own controls (the whole day's end: the lockstep test).
AFTER = 18


@pytest.fixture(scope="module")
def controller(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("controller")
    export(MODEL, out)
    return out


@pytest.fixture
def loop(tmp_path, no_leaks):
    lp = Loop(tmp_path)
    try:
        yield lp
    finally:
        lp.close()


def in_process(controller: Path, tmp: Path) -> pd.DataFrame:
    """The exported controller acting in process on the device's simulation (the building's own controls under
    the actuators), its setpoints as a BACnet REAL carries them (float32), normalized as the device does."""
    from parallel_eplus.deploy.serve.contract import Contract, load_session
    from parallel_eplus.engine.config import SimulationConfig
    from parallel_eplus.engine.simulation import Simulation

    contract = Contract.read(controller)
    session, (inp, out) = load_session(controller, contract)
    low, high = (np.array([o[k] for o in contract.outputs]) for k in ("low", "high"))
    names = [s["name"] for s in contract.sensors]
    sim = Simulation(SimulationConfig(weather="CA", run_days=1, output_dir=str(tmp), relinquish=True,
                                      native_bridge=False))  # fmt: skip
    try:
        sim.launch()
        obs, info = sim.first_observation()
        while True:
            sensors = dict(zip(names, obs[: len(names)].tolist(), strict=True))
            body = {"time": info["time"].isoformat(), "sensors": sensors}
            row = session.run([out], {inp: contract.observation(body)})[0][0]
            sim.send(2 * (row.astype(np.float32).astype(np.float64) - low) / (high - low) - 1)
            obs, _, terminated, info = sim.receive()
            if terminated:
                return pd.read_parquet(Path(info["episode_dir"]) / "steps.parquet")
    finally:
        sim.close()


@pytest.mark.slow
def test_a_day_through_bacnet_equals_the_in_process_controller_step_by_step(loop, controller, tmp_path):
    """Lockstep, the supervisor advancing the clock: every reading and setpoint of the day equal."""
    loop.device()
    loop.supervisor(controller)
    assert loop.wait("supervisor") == 0, loop.log("supervisor")
    assert loop.wait("device") == 0, loop.log("device")
    over_bacnet = loop.steps()
    assert len(over_bacnet) == 96
    reference = in_process(controller, tmp_path / "reference")
    pd.testing.assert_frame_equal(reference, over_bacnet, check_exact=True)
    assert "acted on 96 steps (0 fallbacks)" in loop.log("supervisor")
    assert "relinquished priority 8" in loop.log("supervisor")
    assert loop.log("device").count("priority 8") == 4  # one log line, step 0: every setpoint at 8 from there on


@pytest.mark.slow
@pytest.mark.parametrize("how", ["SIGTERM", "SIGKILL"])
def test_a_killed_supervisor_leaves_the_building_to_its_own_controls_within_one_step(loop, controller, how):
    """SIGTERM: it relinquishes as it goes. SIGKILL: it cannot; the device's watchdog relinquishes its priority at
    the first step it did not act on. Either way the setpoints are the building's own from that step on."""
    loop.device()
    loop.supervisor(controller, "--no-advance")

    async def drive():
        async with Client(loop) as c:
            await c.clock(0, 10)
            await c.until("heartbeat", 10)  # it has acted on step 10: killed before step 10 is run
            loop.procs["supervisor"].send_signal(getattr(signal, how))
            loop.wait("supervisor", 30)
            await c.clock(10, AFTER, supervised=False)

    asyncio.run(drive())
    loop.procs["device"].send_signal(signal.SIGTERM)  # the rest of the day would be the same: stopped, records kept
    assert loop.wait("device") == 130, loop.log("device")
    steps = loop.steps()
    assert len(steps) >= AFTER
    first_own = 10 if how == "SIGTERM" else 11  # SIGKILL: step 10 runs what it wrote for it
    commanded = steps[["west_setpoint_c", "east_setpoint_c", "west_fan_kg_s", "east_fan_kg_s"]].notna().all(axis=1)
    assert commanded[:first_own].all() and not commanded[first_own:].any()
    if how == "SIGTERM":
        assert "relinquished priority 8" in loop.log("supervisor")
    else:
        assert "the supervisor at priority 8 did not act on step 11" in loop.log("device")
    assert loop.procs["supervisor"].returncode == (0 if how == "SIGTERM" else -9)


@pytest.mark.slow
def test_a_lower_priority_write_loses_and_an_operator_override_wins_unfought(loop, controller):
    """A rogue client at 16 never acts; an operator at 5 and one at 8 (the supervisor's own) win from the step
    they wrote; the supervisor logs each once and leaves their slots alone, and takes over again when they go."""
    loop.device()

    async def drive():
        async with Client(loop) as c:
            await c.write("west_setpoint_c", 35.0, priority=16)  # before the supervisor starts
            loop.supervisor(controller, "--no-advance")
            await c.clock(0, 10)
            await c.until("heartbeat", 10)
            await c.write("west_fan_kg_s", 6.5, priority=5)
            await c.write("east_fan_kg_s", 2.5, priority=8)
            await c.clock(10, 20)
            await c.until("heartbeat", 20)
            await c.write("west_fan_kg_s", None, priority=5)
            await c.write("east_fan_kg_s", None, priority=8)
            await c.clock(20, 30)
            loop.procs["supervisor"].send_signal(signal.SIGTERM)
            loop.wait("supervisor", 30)
            await c.write("west_setpoint_c", None, priority=16)
            await c.clock(30, 30 + AFTER - 10, supervised=False)

    asyncio.run(drive())
    loop.procs["device"].send_signal(signal.SIGTERM)  # the rest of the day would be the same: stopped, records kept
    assert loop.wait("device") == 130, loop.log("device")
    steps, log = loop.steps(), loop.log("supervisor")
    assert len(steps) >= 30 + AFTER - 10
    assert steps.west_setpoint_c[:30].notna().all() and (steps.west_setpoint_c[:30] != 35.0).all()
    assert (steps.west_fan_kg_s[10:20] == 6.5).all() and (steps.east_fan_kg_s[10:20] == 2.5).all()
    assert log.count("west_fan_kg_s is overridden at priority 5") == 1
    assert log.count("east_fan_kg_s is overridden at priority 8") == 1
    assert log.count("the override is gone") == 2
    assert steps.west_fan_kg_s[20:30].notna().all() and (steps.west_fan_kg_s[20:30] != 6.5).all()
    assert math.isnan(steps.east_fan_kg_s[20]) and steps.east_fan_kg_s[21:30].notna().all()  # free for a step
    assert steps[["west_setpoint_c", "east_fan_kg_s"]][30:].isna().all().all()  # the rogue gone, the supervisor too


@pytest.mark.slow
def test_in_accelerated_real_time_the_supervisor_follows_the_device_s_clock(loop, controller):
    """A step every 0.5 s: the supervisor acts on each step from when it connects; SIGTERM gives the building back
    within a step (no watchdog warning: it said it left); the stopped device keeps the records so far."""
    loop.device("--step-seconds", "0.5")
    loop.supervisor(controller)

    async def drive():
        async with Client(loop) as c:
            start = await c.read("heartbeat")
            await c.until("heartbeat", 0)
            first = int(await c.read("heartbeat"))
            await c.until("heartbeat", first + 6)
            loop.procs["supervisor"].send_signal(signal.SIGTERM)
            assert loop.wait("supervisor", 30) == 0
            last = int(await c.read("heartbeat"))
            await c.until("step", last + 3)
            return start, first, last

    start, first, last = asyncio.run(drive())
    loop.procs["device"].send_signal(signal.SIGTERM)
    assert loop.wait("device") == 130, loop.log("device")
    steps = loop.steps()
    commanded = steps["west_setpoint_c"].notna()
    # its first answer and its relinquish can each land after the step they were meant for (a loaded machine: the
    # first answer loads onnxruntime's session), so the steps `first` and `last` may be either
    assert start == -1 and not commanded[:first].any() and commanded[first + 1 : last].all()
    assert not commanded[last + 1 :].any()
    assert len(steps) >= last + 2 and "did not act" not in loop.log("device")


@pytest.mark.slow
def test_a_device_with_only_its_points_is_supervised_on_the_supervisor_s_own_clock(loop, controller):
    """A real device's points list: sensors and setpoints, no step, time or heartbeat. The supervisor acts every
    --step-seconds on its own clock (its local time for the clock features) and relinquishes on SIGTERM."""
    loop.device("--step-seconds", "0.3")
    full = PointMap.read(loop.map)
    real = PointMap([p for p in full.points if p.role in ("sensor", "setpoint")], full.device, full.device_instance)
    real.write(loop.tmp / "real.toml")

    async def drive():
        async with Client(loop) as c:
            loop.start("supervisor", "serve", str(controller), "--bacnet", loop.address, "--point-map",
                       str(loop.tmp / "real.toml"), "--local", f"{HOST}:{loop.ports['supervisor']}",
                       "--step-seconds", "0.3")  # fmt: skip
            await c.until("step", 20)
            loop.procs["supervisor"].send_signal(signal.SIGTERM)
            assert loop.wait("supervisor", 30) == 0
            await c.until("step", await c.read("step") + 3)

    asyncio.run(drive())
    loop.procs["device"].send_signal(signal.SIGTERM)
    assert loop.wait("device") == 130, loop.log("device")
    commanded = loop.steps()["west_setpoint_c"].notna()
    assert commanded.sum() >= 5 and not commanded.iloc[-2:].any()
    log = loop.log("supervisor")
    assert "no `time` point" in log and "relinquished priority 8" in log


@pytest.mark.slow
def test_with_no_command_at_any_priority_the_device_runs_the_building_s_own_controls_exactly(loop, tmp_path):
    """Warmed up under its own controls and never commanded, the device's day is `evaluate --baseline`'s."""
    from parallel_eplus.engine.config import SimulationConfig
    from parallel_eplus.engine.simulation import Simulation

    loop.device("--warmup", "builtin")

    async def drive():
        async with Client(loop) as c:
            await c.clock(0, 96, supervised=False)

    asyncio.run(drive())
    assert loop.wait("device") == 0, loop.log("device")
    device = loop.steps()
    sim = Simulation(SimulationConfig(weather="CA", run_days=1, model="baseline", output_dir=str(tmp_path / "b")))
    try:
        sim.launch()
        sim.first_observation()
        terminated = False
        while not terminated:
            sim.send(np.zeros(0))  # the built-in controller: no action
            terminated = sim.receive()[2]
    finally:
        sim.close()
    builtin = pd.read_parquet(glob.glob(str(tmp_path / "b" / "*" / "steps.parquet"))[0])
    assert device[["west_setpoint_c", "east_setpoint_c", "west_fan_kg_s", "east_fan_kg_s"]].isna().all().all()
    pd.testing.assert_frame_equal(device[builtin.columns], builtin, check_exact=True)


@pytest.mark.slow
def test_a_command_outside_a_setpoint_s_limits_or_nan_is_refused_with_value_out_of_range(loop):
    """55 °C, -3 °C, a fan's 0.1 kg/s (below its limit) and NaN at priority 8: each refused with BACnet's error
    (property, value-out-of-range), nothing held at any priority; a command at a limit is taken."""
    from bacpypes3.apdu import ErrorRejectAbortNack

    loop.device()
    points = {p.name: p for p in PointMap.read(loop.map).role("setpoint")}
    setpoint, fan = points["west_setpoint_c"], points["west_fan_kg_s"]
    impossible = [("west_setpoint_c", 55.0), ("west_setpoint_c", -3.0), ("west_setpoint_c", math.nan),
                  ("west_fan_kg_s", 0.1), ("west_fan_kg_s", fan.high + 1.0)]  # fmt: skip
    assert fan.low > 0.1 and setpoint.low > -3.0 and setpoint.high < 55.0

    async def drive():
        refused = []
        async with Client(loop) as c:
            for name, value in impossible:
                with pytest.raises(ErrorRejectAbortNack) as e:
                    await c.write(name, value, priority=8)
                refused.append(str(e.value))
            await c.write("west_setpoint_c", setpoint.high, priority=8)  # at its limit: taken
            held = await c.read("west_setpoint_c")
            await c.write("west_setpoint_c", None, priority=8)
            fan_now = await c.read("west_fan_kg_s")
        return refused, held, fan_now

    refused, held, fan_now = asyncio.run(drive())
    assert all("value-out-of-range" in r.replace("valueOutOfRange", "value-out-of-range") for r in refused), refused
    assert held == pytest.approx(setpoint.high) and math.isnan(fan_now)  # nothing of the refused ones applied
    assert loop.log("device").count("(value-out-of-range)") == len(impossible)


def _said_within(loop, name: str, text: str, seconds: float) -> str:
    """The line of `name`'s log holding `text`, once it comes; asserted to come within `seconds` of "supervising"."""
    deadline = time.monotonic() + 60
    while text not in loop.log(name):
        assert loop.procs[name].poll() is None and time.monotonic() < deadline, loop.log(name)
        time.sleep(0.1)
    lines = loop.log(name).splitlines()
    stamp = [dt.datetime.strptime(line[:23], "%Y-%m-%d %H:%M:%S,%f") for line in lines if "supervising" in line]
    said = next(line for line in lines if text in line)
    assert (dt.datetime.strptime(said[:23], "%Y-%m-%d %H:%M:%S,%f") - stamp[0]).total_seconds() <= seconds, said
    return said


@pytest.mark.slow
def test_a_supervisor_that_cannot_reach_its_device_says_why_within_seconds(loop, controller):
    """Nothing at the address: no I-Am, no read, said so. A local address on the device's own port (another
    loopback IP): the supervisor's requests reach its own socket, said so, with the remedy. Each within seconds."""
    loop.device()
    nowhere = f"{HOST}:{loop.ports['client']}"  # a free port: no device there
    loop.start("nowhere", "serve", str(controller), "--bacnet", nowhere, "--point-map", str(loop.map),
               "--local", f"{HOST}:{loop.ports['supervisor']}")  # fmt: skip
    said = _said_within(loop, "nowhere", "answered neither a Who-Is (no I-Am) nor a read in 3 s", 8)
    assert "is a device running at that address and port" in said
    loop.procs["nowhere"].terminate()
    loop.wait("nowhere", 30)
    loop.start("shared", "serve", str(controller), "--bacnet", loop.address, "--point-map", str(loop.map),
               "--local", f"127.0.0.2:{loop.ports['device']}")  # fmt: skip
    said = _said_within(loop, "shared", "does not answer", 8)
    assert "on the device's own port" in said and "give --local another port" in said


def test_the_point_map_is_checked_against_the_contract(tmp_path):
    m = PointMap.generate([("a_c", "C")], [("s_c", "C", 10.0, 40.0)], lockstep=True, device=f"{HOST}:47808")
    path = m.write(tmp_path / "points.toml")
    back = PointMap.read(path)
    assert back == m
    back.check(["a_c"], ["s_c"])
    with pytest.raises(ValueError, match="no sensor point for b_c"):
        back.check(["a_c", "b_c"], ["s_c"])
    back.points[0].role = "thermostat"
    with pytest.raises(ValueError, match="role 'thermostat'"):
        back.check(["a_c"], ["s_c"])


@pytest.mark.parametrize("priority", [1, 7, 17])
def test_a_supervisor_priority_outside_8_to_16_is_refused(priority, tmp_path):
    from parallel_eplus.deploy.bacnet.supervisor import SupervisorConfig

    with pytest.raises(ValueError, match="8-16"):
        SupervisorConfig(tmp_path, f"{HOST}:47808", tmp_path / "points.toml", priority=priority)
