"""BAC0 as both ends use it: a BACnet/IP application on one address, and BAC0's own logging sent to ours.

BAC0 (on bacpypes3) starts the application and builds the device's local objects; reads and writes go through
bacpypes3's typed calls on that application (`read_property_multiple`, `write_property` with a priority), so a
setpoint crosses as a REAL, never as text.
"""

from __future__ import annotations

import asyncio
import ipaddress
import logging
import math

log = logging.getLogger(__name__)

DEFAULT_PORT = 47808  # BACnet/IP's UDP port (0xBAC0)


def split_address(text: str) -> tuple[str, int | None, int]:
    """An address "host[/mask][:port]" -> (host, mask or None, port). The host must be an IPv4 address (BACnet/IP)."""
    host, _, port = text.strip().partition(":")
    host, _, mask = host.partition("/")
    try:
        ipaddress.IPv4Address(host)
    except ValueError:
        raise ValueError(f"BACnet address {text!r}: give an IPv4 address, as host[/mask][:port]") from None
    if port and not port.isdigit() or mask and not mask.isdigit():
        raise ValueError(f"BACnet address {text!r}: give host[/mask][:port], e.g. 192.168.1.20/24:47808")
    return host, int(mask) if mask else None, int(port) if port else DEFAULT_PORT


def peer(text: str) -> str:
    """A device's address as bacpypes3 takes it ("host:port")."""
    host, _, port = split_address(text)
    return f"{host}:{port}"


def quiet() -> None:
    """BAC0's loggers print to stdout at INFO through their own handlers: send them to ours, WARNING and up."""
    for name, logger in list(logging.Logger.manager.loggerDict.items()):
        if name.startswith("BAC0_Root") and isinstance(logger, logging.Logger):
            logger.handlers.clear()
            logger.propagate = True
            logger.setLevel(logging.ERROR if name.endswith("ObjectFactory") else logging.WARNING)  # "no COV" noise


async def start(address: str, device_id: int, name: str, bbmd: str | None = None, ttl: int = 900):
    """A BAC0 application on `address` ("host[/mask][:port]"; loopback defaults to /8, any other host to /24),
    registered as a foreign device with `bbmd` when given; returned once it has announced itself (I-Am)."""
    import BAC0

    quiet()
    host, mask, port = split_address(address)
    mask = mask or (8 if ipaddress.IPv4Address(host).is_loopback else 24)
    foreign = {"bbmdAddress": peer(bbmd), "bbmdTTL": ttl} if bbmd else {}
    app = BAC0.start(ip=f"{host}/{mask}", port=port, deviceId=device_id, localObjName=name, ping=False, **foreign)
    quiet()  # loggers BAC0 made while starting
    for _ in range(500):
        if app._initialized:
            break
        await asyncio.sleep(0.01)
    log.info("BACnet/IP device %d (%s) on %s:%d", device_id, name, host, port)
    return app


async def stop(app) -> None:
    """Close the application's UDP socket and BAC0's tasks."""
    await app._disconnect()


def real(value) -> float:
    """A REAL as a Python float (NaN where the value is not a number)."""
    try:
        return float(value)
    except (TypeError, ValueError):
        return math.nan


def commands(priority_array) -> dict[int, float]:
    """A priority array as {priority (1-16): value} for the slots that hold a command."""
    out = {}
    for i, slot in enumerate(priority_array or []):
        if getattr(slot, "null", ()) is None:  # bacpypes3: a slot holding a value has no `null`
            out[i + 1] = real(getattr(slot, slot._choice))
    return out
