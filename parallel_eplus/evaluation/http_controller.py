"""A controller served over HTTP (`parallel-eplus serve`) driving an evaluation episode: `evaluate --controller-url`.

Each step's sensor readings go out as `POST /act` in physical units with the step's time, and the setpoints that
come back are what EnergyPlus gets: the same path a building-management system takes. Standard library only (one
kept-alive connection per episode), so the evaluation adds no HTTP client dependency.
"""

from __future__ import annotations

import datetime as dt
import hashlib
import http.client
import json
import logging
import math
import os
import time
from pathlib import Path
from urllib.parse import urlsplit

import numpy as np

from parallel_eplus.buildings.building import load_building, weather_path
from parallel_eplus.buildings.datacenter import DEFAULT
from parallel_eplus.buildings.pricing.bill import DemandTracker
from parallel_eplus.buildings.scaling import to_unit
from parallel_eplus.buildings.weather.forecast import WEATHER, PerfectForecast

log = logging.getLogger(__name__)

TOKEN_VARIABLE = "PARALLEL_EPLUS_TOKEN"  # the bearer token a served controller asks for, when no --token-file


def client_token(token_file: Path | None) -> str | None:
    """The bearer token `evaluate --controller-url` sends: the first line of `token_file`, else the environment's
    PARALLEL_EPLUS_TOKEN, else None. Never logged, never in an error message."""
    if token_file is not None:
        lines = Path(token_file).read_text().strip().splitlines()
        if not lines or not lines[0].strip():
            raise ValueError(f"--token-file {token_file} is empty: put the token on its first line")
        return lines[0].strip()
    return os.environ.get(TOKEN_VARIABLE, "").strip() or None


class HttpController:
    """Callable (observation, info) -> normalized action, asking the server at `url` for each step (with
    `Authorization: Bearer <token>` when given one)."""

    def __init__(self, url: str, timeout_s: float = 30.0, token: str | None = None):
        parts = urlsplit(url if "://" in url else f"http://{url}")
        if parts.scheme != "http" or not parts.hostname:
            raise ValueError(f"--controller-url {url!r}: give http://HOST:PORT (as `parallel-eplus serve` prints)")
        self.url, self.host, self.port, self.timeout_s = url, parts.hostname, parts.port or 80, timeout_s
        self.auth = {"Authorization": f"Bearer {token}"} if token else {}
        if token and not (self.host in ("localhost", "::1") or self.host.startswith("127.")):
            log.warning("PLAIN HTTP to %s: the bearer token crosses the network in clear", self.host)
        self.conn: http.client.HTTPConnection | None = None
        self.act_ms: list[float] = []  # each POST /act's round trip, ms
        self.contract = self._request("GET", "/contract")
        self.names = [i["name"] for i in self.contract["inputs"] if i["source"] == "sensor"]
        self.low = np.array([o["low"] for o in self.contract["outputs"]])
        self.high = np.array([o["high"] for o in self.contract["outputs"]])
        self.outputs = [o["name"] for o in self.contract["outputs"]]
        self.planner = self.contract.get("kind") == "planner"
        if self.planner:  # a planner is also told the last setpoints, a forecast, and its last plan
            self.last = {o["name"]: float(o["initial"]) for o in self.contract["outputs"]}
            self.plan = None
            self.forecasts: dict[str, PerfectForecast] = {}
        self.demand: DemandTracker | None = None  # a planner that prices demand charges: the month's peaks
        if self.planner and self.contract.get("demand_peaks_kw"):
            tariff = load_building(self.building()).comfort.kpis.tariffs["Electricity"]
            self.demand = DemandTracker(tariff, self.contract["control_step_s"] / 60)
            self.charges = self.contract["demand_peaks_kw"]["charges"]
            here = tariff.demand_names
            if here != self.charges:
                raise ValueError(
                    f"controller at {self.url} prices demand charges {self.charges}; the tariff here has "
                    f"{here}: the client keeps the peaks with the building's own tariff"
                )
            self.meter = self.contract["planner"]["demand"]["power"]

    def _request(self, method: str, path: str, body: dict | None = None) -> dict:
        payload = None if body is None else json.dumps(body).encode()
        headers = ({"Content-Type": "application/json"} if payload is not None else {}) | self.auth
        for attempt in (0, 1):  # a kept-alive connection the server closed is opened again, once
            if self.conn is None:
                self.conn = http.client.HTTPConnection(self.host, self.port, timeout=self.timeout_s)
            try:
                self.conn.request(method, path, payload, headers)
                response = self.conn.getresponse()
                text = response.read()
                break
            except (OSError, http.client.HTTPException) as e:
                self.close()
                if attempt:
                    raise ValueError(f"controller at {self.url}: {method} {path} failed ({e}); is it serving?") from e
        if response.status == 401:  # the server's words name the header, never the token
            how = (
                "it refused the token given (--token-file, else $" + TOKEN_VARIABLE + ")"
                if self.auth
                else "it needs a token: give --token-file FILE (the token on its first line) or set " + TOKEN_VARIABLE
            )
            raise ValueError(f"controller at {self.url} answered 401 to {method} {path}: {how} ({text[:200]!r})")
        if response.status != 200:
            raise ValueError(f"controller at {self.url} answered {response.status} to {method} {path}: {text[:300]!r}")
        return json.loads(text)

    def building(self) -> str | None:
        """The spec the served controller was exported for, as the sweep names it (None: the data center); a
        different version of the spec here than there is refused."""
        b = self.contract["building"]
        spec = load_building(None if b["name"] == DEFAULT.name else b["name"]).spec
        if hashlib.sha256(Path(spec.path).read_bytes()).hexdigest() != b["sha256"]:
            raise ValueError(
                f"controller at {self.url} was exported for another version of building {b['name']} "
                f"(spec sha256 {b['sha256'][:12]}…; here {spec.path})"
            )
        return None if b["name"] == DEFAULT.name else b["name"]

    def __call__(self, obs: np.ndarray, info: dict) -> np.ndarray:
        # The readings as the in-process policy sees them: the env's float32 observation (clipped to the spec's
        # bounds), in physical units.
        sensors = {n: float(v) for n, v in zip(self.names, obs[: len(self.names)].tolist(), strict=True)}
        body = {"time": info["time"].isoformat(), "sensors": sensors}
        if self.planner:
            body |= {"last_setpoints": self.last, "forecast": self._forecast(info), "plan": self.plan}
            if self.guard is not None:  # `guard_k`'s state, as the last answer left it
                body["guard"] = self.guard
            if self.contract.get("rule"):  # the rule it rides: what it reads beyond the sensors, and its memory
                body["rule_readings"] = {r["name"]: float(info[r["name"]]) for r in self.contract["rule"]["readings"]}
                body["rule_state"] = self.rule_state
        if self.demand is not None:  # the building's meter: the month's running peaks so far, as its BMS keeps them
            self.demand.observe(info["time"], sensors[self.meter])
            body["demand_peaks_kw"] = self.demand.month_peaks(self.charges, info["time"])
        start = time.perf_counter()
        answer = self._request("POST", "/act", body)
        self.act_ms.append(1000 * (time.perf_counter() - start))  # as the integrator sees it: the round trip
        physical = np.array([answer["setpoints"][n]["value"] for n in self.outputs])
        if not all(map(math.isfinite, physical)):
            raise ValueError(f"controller at {self.url} returned non-finite setpoints: {answer}")
        if self.planner:
            self.last, self.plan = dict(zip(self.outputs, physical.tolist(), strict=True)), answer.get("plan")
            self.guard, self.rule_state = answer.get("guard"), answer.get("rule_state")
            self.fallbacks += bool(answer.get("fallback"))
        return to_unit(physical, self.low, self.high)

    fallbacks = 0  # answers a served planner marked as fallbacks
    guard = None  # a served planner's `guard`, sent back with the next request
    rule_state = None  # a served planner's rule's memory (`baseline_source=rule`), sent back with the next request

    def _forecast(self, info: dict) -> dict[str, list[float]]:
        """The coming steps' weather from the episode's own file, as the contract's forecast block asks for it: the
        perfect forecast the in-process planner reads."""
        block = self.contract["forecast"]
        file = info.get("weather_file") or str(weather_path(self.building(), info["weather"]))
        if file not in self.forecasts:
            self.forecasts[file] = PerfectForecast(Path(file))
        step = dt.timedelta(seconds=block["step_s"])
        times = [info["time"] + step * (k + 1) for k in range(block["steps"])]
        values = self.forecasts[file].truth(times)
        names = [v["name"] for v in block["variables"]]
        if tuple(names) != WEATHER:
            raise ValueError(f"controller at {self.url} asks for forecast {names}; this client sends {WEATHER}")
        return {n: values[:, i].tolist() for i, n in enumerate(names)}

    def latency(self) -> dict[str, float] | None:
        """The POST /act round trips so far: p50, p99 and mean, ms (None: none yet)."""
        if not self.act_ms:
            return None
        ms = np.array(self.act_ms)
        return {"requests": len(ms), "p50": float(np.percentile(ms, 50)), "p99": float(np.percentile(ms, 99)),
                "mean": float(ms.mean())}  # fmt: skip

    def close(self) -> None:
        if (summary := self.latency()) is not None and self.conn is not None:
            log.info("%s: %d POST /act, p50 %.1f ms, p99 %.1f ms", self.url, summary["requests"], summary["p50"],
                     summary["p99"])  # fmt: skip
        if self.conn is not None:
            self.conn.close()
            self.conn = None
