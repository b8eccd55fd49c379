"""The wire format: round trips, control frames, and malformed or truncated frames."""

from __future__ import annotations

import os
import stat
import struct

import numpy as np
import pytest

from parallel_eplus.engine.pipes import frames, pipe, spin
from parallel_eplus.errors import ProtocolError


@pytest.mark.parametrize("values", [[], [1.5], [23.5, -20.0, 1e9, 0.1, 7.0, 3.25]])
def test_data_frame_round_trip(values):
    frame = frames.encode(values)
    assert frame[:4] == struct.pack("<i", len(values))
    code, out = frames.decode(frame)
    assert code == frames.DATA
    np.testing.assert_array_equal(out, values)


@pytest.mark.parametrize("code", [frames.END, frames.ERROR])
def test_control_frame_round_trip(code):
    code_out, out = frames.decode(frames.encode([1.0, 2.0], code))
    assert code_out == code
    np.testing.assert_array_equal(out, [1.0, 2.0])


def test_unknown_control_code_is_rejected():
    with pytest.raises(ProtocolError, match="control code"):
        frames.decode(struct.pack("<ii", -7, 0))
    with pytest.raises(ValueError):
        frames.encode([1.0], code=-7)


def test_absurd_count_is_rejected():
    with pytest.raises(ProtocolError, match="count"):
        frames.decode(struct.pack("<i", frames.MAX_VALUES + 1))


def test_truncated_frame_is_an_error_not_zeros():
    frame = frames.encode([1.0, 2.0, 3.0])
    with pytest.raises(ProtocolError):
        frames.decode(frame[:-3])


def test_pipe_pair_is_private_unique_and_removed():
    a, b = pipe.PipePair(), pipe.PipePair()
    try:
        assert a.dir != b.dir
        assert stat.S_IMODE(os.stat(a.dir).st_mode) == 0o700
        assert stat.S_ISFIFO(os.stat(a.act_path).st_mode)
        assert stat.S_ISFIFO(os.stat(a.obs_path).st_mode)
    finally:
        a.close()
        b.close()
    assert not a.dir.exists() and not b.dir.exists()


def test_pipe_pair_times_out_and_reads_truncation():
    pp = pipe.PipePair()
    try:
        with pytest.raises(TimeoutError):
            pp.recv(timeout=0.05)
        # A writer on the other end sends half a frame: the reader waits, then times out.
        fd = os.open(pp.obs_path, os.O_WRONLY)
        os.write(fd, frames.encode([1.0, 2.0])[:7])
        with pytest.raises(TimeoutError, match="7 bytes of a frame"):
            pp.recv(timeout=0.05)
        os.write(fd, frames.encode([1.0, 2.0])[7:] + frames.encode([3.0], frames.END))  # the rest, then one more
        assert [(c, v.tolist()) for c, v in (pp.recv(1.0), pp.recv(1.0))] == [
            (frames.DATA, [1.0, 2.0]),
            (frames.END, [3.0]),
        ]
        os.close(fd)
    finally:
        pp.close()


def test_both_sides_spin_only_where_a_core_is_free(monkeypatch):
    """spin.auto_spins: one worker on 2 idle cores spins on both sides; 2 workers, EnergyPlus only (the learner
    would take a core from them); on a machine busy with other runs both block."""
    monkeypatch.setattr(os, "cpu_count", lambda: 2)
    for load, workers, spins in ((2.0, 1, (spin.SPIN_S, spin.SPIN_S)), (2.6, 2, (0.0, spin.SPIN_S)),
                                 (14.0, 1, (0.0, 0.0)), (4.0, 2, (0.0, 0.0))):  # fmt: skip
        monkeypatch.setattr(os, "getloadavg", lambda load=load: (load, load, load))
        assert spin.auto_spins(workers) == spins, (load, workers)
