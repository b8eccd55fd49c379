"""The BACnet loop's harness: a device and a supervisor, each a `parallel-eplus` process, and the test's own BAC0
client (an operator, a rogue client or a clock), over UDP on 127.0.0.1 with a port each."""

from __future__ import annotations

import asyncio
import glob
import socket
import subprocess
import sys
import time
from pathlib import Path

import pandas as pd

from parallel_eplus.deploy.bacnet.point_map import PointMap

HOST = "127.0.0.1"


def udp_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind((HOST, 0))
        return s.getsockname()[1]


def udp_bound(ports: list[int]) -> list[int]:
    """Which of `ports` a UDP socket on this machine still holds (/proc/net/udp, hex ports)."""
    held = set()
    for line in Path("/proc/net/udp").read_text().splitlines()[1:]:
        held.add(int(line.split()[1].split(":")[1], 16))
    return [p for p in ports if p in held]


class Loop:
    """A device and a supervisor, each a `parallel-eplus` process with its log in a file, and the test's client;
    every one of them ended, and its UDP port checked free, at the end."""

    def __init__(self, tmp: Path):
        self.tmp, self.procs, self.ports = tmp, {}, {k: udp_port() for k in ("device", "supervisor", "client")}
        self.map = tmp / "points.toml"
        self.address = f"{HOST}:{self.ports['device']}"

    def start(self, name: str, *args: str) -> subprocess.Popen:
        log = (self.tmp / f"{name}.log").open("w")
        self.procs[name] = subprocess.Popen([sys.executable, "-m", "parallel_eplus.cli", *args], stdout=log,
                                            stderr=subprocess.STDOUT, text=True)  # fmt: skip
        return self.procs[name]

    def device(self, *extra: str) -> None:
        self.start("device", "simulate", "--bacnet", self.address, "--days", "1", "--weather", "CA",
                   "--point-map", str(self.map), "--output-dir", str(self.tmp / "episodes"), *extra)  # fmt: skip
        deadline = time.monotonic() + 120
        while not self.map.is_file():  # written once its objects are up
            assert self.procs["device"].poll() is None, self.log("device")
            assert time.monotonic() < deadline, self.log("device")
            time.sleep(0.1)

    def supervisor(self, controller: Path, *extra: str) -> None:
        self.start("supervisor", "serve", str(controller), "--bacnet", self.address, "--point-map", str(self.map),
                   "--local", f"{HOST}:{self.ports['supervisor']}", *extra)  # fmt: skip

    def log(self, name: str) -> str:
        return (self.tmp / f"{name}.log").read_text()

    def wait(self, name: str, timeout: float = 120) -> int:
        return self.procs[name].wait(timeout=timeout)

    def steps(self) -> pd.DataFrame:
        return pd.read_parquet(glob.glob(str(self.tmp / "episodes" / "*" / "steps.parquet"))[0])

    def close(self) -> None:
        for p in self.procs.values():
            if p.poll() is None:
                p.terminate()
                p.wait(timeout=60)
        assert udp_bound(list(self.ports.values())) == []  # no UDP socket left behind


class Client:
    """The test's BACnet client (BAC0): reads a point, writes at a priority, drives the lockstep clock."""

    def __init__(self, lp: Loop):
        self.lp, self.map = lp, PointMap.read(lp.map)

    async def __aenter__(self):
        from parallel_eplus.deploy.bacnet import app as bacnet

        self.app = await bacnet.start(f"{HOST}:{self.lp.ports['client']}", 597, "test client")
        return self

    async def __aexit__(self, *exc):
        from parallel_eplus.deploy.bacnet import app as bacnet

        await bacnet.stop(self.app)

    def _point(self, name: str):
        return next(p for p in self.map.points if p.name == name)

    async def read(self, name: str) -> float:
        from bacpypes3.pdu import Address
        from bacpypes3.primitivedata import ObjectIdentifier

        app = self.app.this_application.app
        value = await app.read_property(Address(self.lp.address), ObjectIdentifier(self._point(name).object_id),
                                        "present-value")  # fmt: skip
        return float(value)

    async def write(self, name: str, value: float | None, priority: int | None = None) -> None:
        from bacpypes3.pdu import Address
        from bacpypes3.primitivedata import Null, ObjectIdentifier, Real

        app = self.app.this_application.app
        v = Null(()) if value is None else Real(value)
        where = Address(self.lp.address), ObjectIdentifier(self._point(name).object_id)
        await app.write_property(*where, "present-value", v, priority=priority)

    async def until(self, name: str, at_least: float, timeout: float = 60) -> None:
        deadline = time.monotonic() + timeout
        while await self.read(name) < at_least:
            assert time.monotonic() < deadline, f"{name} never reached {at_least}"
            await asyncio.sleep(0.005)

    async def clock(self, start: int, stop: int, supervised: bool = True) -> None:
        """Advance steps start..stop-1 once the supervisor has acted on each (its heartbeat), or at once."""
        for k in range(start, stop):
            await self.until("step", k)
            if supervised:
                await self.until("heartbeat", k)
            await self.write("advance", float(k + 1))
