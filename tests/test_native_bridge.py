"""The two EnergyPlus-side bridges (the Python callback and the C one, eplus_side/native.py) against real EnergyPlus."""

from __future__ import annotations

import numpy as np
import pytest

from parallel_eplus.buildings.datacenter import STEPS_PER_DAY


def _bridges() -> list:
    """Both EnergyPlus-side bridges; the C one only where it compiles (it does wherever CI runs)."""
    from parallel_eplus.engine.eplus_side import native

    c = pytest.param(True, id="c-bridge")
    if native.bridge_library() is None:
        c = pytest.param(True, id="c-bridge", marks=pytest.mark.skip(reason="no C compiler"))
    return [c, pytest.param(False, id="python-bridge")]


@pytest.mark.slow
def test_c_and_python_bridges_step_identical_trajectories(no_leaks):
    """The C bridge is the Python one's steady state moved to C: same actions, same physics, bit for bit, whether
    its side spins for actions or blocks in one read per action (spin.auto_spins picks by the machine's load), and
    whether each action arrives while EnergyPlus still computes the next timestep's start or long after it needs
    it (an env slower than EnergyPlus's work before the actuators: it then waits at them)."""
    import time

    from parallel_eplus.engine.config import SimulationConfig
    from parallel_eplus.engine.episode import bridge_counters
    from parallel_eplus.engine.eplus_side import native
    from parallel_eplus.engine.simulation import Simulation

    if native.bridge_library() is None:
        pytest.skip("no C compiler")
    actions = np.clip(np.random.default_rng(3).normal(size=(STEPS_PER_DAY, 4)), -1, 1)
    runs = []
    for use_c, spin_s, delay_s in ((True, 0.002, 0.0), (True, 0.0, 0.0), (True, 0.0, 0.002), (False, None, 0.0)):
        sim = Simulation(SimulationConfig(run_days=1, native_bridge=use_c, spin_s=spin_s))
        assert (sim.process.native_bridge is not None) == use_c
        try:
            obs, _ = sim.start()
            trajectory, terminated = [obs], False
            for a in actions:
                time.sleep(delay_s)
                sim.send(a)
                obs, r, terminated, info = sim.receive()
                trajectory.append(np.append(obs, [r, info["time"].timestamp()]))
            assert terminated
            runs.append(np.concatenate(trajectory))
            if use_c:  # every action after the first read where it is applied, EnergyPlus computing meanwhile
                counters = bridge_counters(sim.episode_dir)
                assert counters["exchanges"] == len(actions) - 1 and counters["ahead_s"] > 0, counters
        finally:
            sim.close()
    for run in runs[1:]:
        np.testing.assert_array_equal(runs[0], run)


@pytest.mark.slow
@pytest.mark.parametrize("use_c", _bridges())
def test_a_malformed_action_frame_stops_energyplus_with_the_reason(use_c, no_leaks):
    from parallel_eplus.engine.config import SimulationConfig
    from parallel_eplus.engine.pipes import frames
    from parallel_eplus.engine.simulation import Simulation
    from parallel_eplus.errors import EnergyPlusError

    sim = Simulation(SimulationConfig(run_days=1, native_bridge=use_c))
    try:
        sim.start()
        sim.send(np.zeros(4))
        sim.receive()  # one exchange first, so the C bridge is armed
        sim.process.pipes.send(frames.encode([1.0, 2.0]))  # two values where EnergyPlus expects four
        with pytest.raises(EnergyPlusError, match=r"failed \(status") as e:
            sim.receive()
        assert "expected an action of 4 values" in str(e.value)
    finally:
        sim.close()


def test_the_c_bridge_compiles_into_a_fresh_cache_or_falls_back_with_a_warning(tmp_path, monkeypatch, caplog):
    from parallel_eplus.engine.eplus_side import native

    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    native.bridge_library.cache_clear()
    try:
        if native.bridge_library() is None:  # this machine has no compiler: it says so
            assert "Python bridge" in caplog.text
        else:
            (lib,) = (tmp_path / "parallel-eplus").glob("eplus_callback-*.so")
            assert native.bridge_library() == str(lib)
        native.bridge_library.cache_clear()
        monkeypatch.setenv("CC", str(tmp_path / "no-such-cc"))
        for old in (tmp_path / "parallel-eplus").glob("*.so"):
            old.unlink()
        assert native.bridge_library() is None
        assert "the Python bridge steps EnergyPlus instead" in caplog.text
    finally:
        native.bridge_library.cache_clear()
