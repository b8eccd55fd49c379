"""The frames on the wire between the env and EnergyPlus: their format, and reading them from a non-blocking fd.

Frame: little-endian int32 count, then `count` float64 values (the paper's bare vectors). A negative
count is a control frame: the code, then an int32 count and its values. END carries the final real
observation; ERROR carries an exit status. Anything else, or a frame cut short, is a ProtocolError.
Both sides of the pipes (engine/pipes/pipe.py's PipePair, the EnergyPlus side's bridge) speak it.
"""

from __future__ import annotations

import datetime as dt
import functools
import os
import select
import struct
import time
from collections.abc import Callable

import numpy as np

from parallel_eplus.engine.pipes.spin import SPIN_S
from parallel_eplus.errors import ProtocolError

DATA = 0
END = -1
ERROR = -2
CONTROL_CODES = (END, ERROR)
TIME_FIELDS = 4  # observation frames start with year, day of year, hour, minute; sensors follow
MAX_VALUES = 4096  # far above any real frame; a larger count means a corrupt stream


_INT = struct.Struct("<i")
_F8 = np.dtype("<f8")


@functools.lru_cache(maxsize=16)
def _data_struct(n: int) -> struct.Struct:
    return struct.Struct(f"<i{n}d")


def encode(values, code: int = DATA) -> bytes:
    """One frame as bytes: written with a single write, so it arrives whole (frames < PIPE_BUF)."""
    if isinstance(values, np.ndarray):
        values = values.ravel().tolist()
    elif not isinstance(values, (list, tuple)):
        values = list(values)
    if code == DATA:
        return _data_struct(len(values)).pack(len(values), *values)
    if code not in CONTROL_CODES:
        raise ValueError(f"unknown control code {code}")
    payload = np.ascontiguousarray(values, dtype="<f8").tobytes()
    return _INT.pack(code) + _INT.pack(len(payload) // 8) + payload


def parse(buf: bytes | bytearray) -> tuple[int, np.ndarray, int] | None:
    """The first whole frame in `buf` as (code, values, its length in bytes); None until all of it is there.

    A bad header is a ProtocolError as soon as it has arrived. From `bytes` (immutable) the values are a
    read-only view, not a copy.
    """
    if len(buf) < 4:
        return None
    (count,) = _INT.unpack_from(buf)
    code, header = DATA, 4
    if count < 0:
        code = count
        if code not in CONTROL_CODES:
            raise ProtocolError(f"malformed frame: unknown control code {code}")
        if len(buf) < 8:
            return None
        (count,) = _INT.unpack_from(buf, 4)
        header = 8
    if not 0 <= count <= MAX_VALUES:
        raise ProtocolError(f"malformed frame: value count {count} outside 0..{MAX_VALUES}")
    end = header + 8 * count
    if len(buf) < end:
        return None
    if isinstance(buf, bytes):
        return code, np.frombuffer(buf, _F8, count, header), end
    return code, np.frombuffer(bytes(buf[header:end]), _F8), end


def decode(data: bytes) -> tuple[int, np.ndarray]:
    """Exactly one frame from bytes; a frame cut short is a ProtocolError."""
    frame = parse(data)
    if frame is None or frame[2] != len(data):
        raise ProtocolError(f"malformed frame: {len(data)} bytes are not one whole frame")
    return frame[0], frame[1]


class FrameReader:
    """Frames from a non-blocking fd. Each read takes whatever has arrived, so a frame written whole
    (ours are) costs one read, and the rare split frame is reassembled.

    Why spin: a process that sleeps in read() is woken through the scheduler, which costs ~25-125 us
    per hand-off across cores on these machines (two per step), more than the exchange itself. A
    short spin sees the other side's write at once; past it we block in `wait(bytes_so_far)`, so an
    idle peer costs no CPU. EOF (the writer is gone) is a ProtocolError.
    """

    def __init__(self, fd: int):
        self.fd = fd
        self.buf = bytearray()
        self._poll = select.poll()  # spinning asks poll(0), not a read that raises BlockingIOError (2x dearer)
        self._poll.register(fd, select.POLLIN)

    def read(self, wait: Callable[[int], None], spin_s: float = SPIN_S) -> tuple[int, np.ndarray]:
        spin_until = None
        while True:
            if self.buf:
                frame = parse(self.buf)
                if frame is not None:
                    del self.buf[: frame[2]]
                    return frame[0], frame[1]
            if spin_s <= 0:  # no spin: block until readable (a select when the frame is already there)
                wait(len(self.buf))
            elif not self._poll.poll(0):  # (a frame is rarely there yet: asking costs less than a failed read)
                if spin_until is None:
                    spin_until = time.perf_counter() + spin_s
                self._await(wait, spin_until)
            try:
                chunk = os.read(self.fd, 65536)
            except BlockingIOError:  # `wait` returned with nothing to read after all
                continue
            if not chunk:
                raise ProtocolError(f"pipe closed after {len(self.buf)} bytes of a frame")
            if not self.buf:  # the usual case: the chunk is one whole frame, read without a copy
                frame = parse(chunk)
                if frame is not None and frame[2] == len(chunk):
                    return frame[0], frame[1]
            self.buf += chunk

    def _await(self, wait: Callable[[int], None], spin_until: float) -> None:
        """Until the fd is readable: yield the core and poll again until `spin_until`; then block in `wait`."""
        poll = self._poll.poll
        while time.perf_counter() < spin_until:  # with no spin, block at once: a yield could cost a time slice
            os.sched_yield()  # let a runnable process on this core go first
            if poll(0):
                return
        wait(len(self.buf))

    def clear(self) -> None:
        self.buf.clear()


def wait_readable(fd: int) -> Callable[[int], None]:
    """The EnergyPlus side's wait: block until the env writes (or goes away)."""
    return lambda got: select.select([fd], [], [])


_DAY_STARTS: dict[tuple[float, float], dt.datetime] = {}
_TIMES_OF_DAY: dict[tuple[float, float], dt.timedelta] = {}


def frame_time(values) -> dt.datetime:
    """When an observation frame was taken, from its first TIME_FIELDS values (year, day, hour, minute).

    Per step: a datetime plus a timedelta, both cached (building a timedelta from keywords cost more than
    the rest of the observation's bookkeeping)."""
    if isinstance(values, np.ndarray):
        values = values[:TIME_FIELDS].tolist()  # floats: cheaper than numpy scalars
    year, day_of_year, hour, minute = values[:TIME_FIELDS]
    start = _DAY_STARTS.get((year, day_of_year))
    if start is None:
        start = _DAY_STARTS[year, day_of_year] = dt.datetime(int(year), 1, 1) + dt.timedelta(days=day_of_year - 1)
    offset = _TIMES_OF_DAY.get((hour, minute))
    if offset is None:
        offset = _TIMES_OF_DAY[hour, minute] = dt.timedelta(hours=hour, minutes=minute)
    return start + offset
