"""BOPTEST's service API over HTTP (FastAPI on uvicorn), as its OpenAPI description states it
(ibpsa/project1-boptest, service/web/server/docs/openapi.yaml): `GET /testcases`, `POST /testcases/{name}/select`,
then per test `PUT /initialize/{testid}`, `POST /advance/{testid}`, ... and `GET /version`. Answers carry BOPTEST's
envelope `{"message", "payload", "status"}` (select its `{"testid"}`; status and stop plain text, as the description
has them); a refusal is the same envelope with a 4xx status and a message naming what is wrong, never a crash.

Access as `serve` has it (deploy/serve/server.py): loopback by default, a bearer token required off it. Refusals are
logged with their reason, tests' starts and ends at INFO, every request with its status and time only with `-v`
(a line per control step is a year's 35,040), never a token.
"""

from __future__ import annotations

import json
import logging
import math
from pathlib import Path

from fastapi import FastAPI, Request
from fastapi.responses import JSONResponse, PlainTextResponse
from starlette.concurrency import run_in_threadpool

from parallel_eplus.deploy.boptest.registry import Registry
from parallel_eplus.deploy.boptest.test import TestError
from parallel_eplus.deploy.serve.contract import InputError
from parallel_eplus.deploy.serve.server import BearerToken, RequestLog, _body, check_access

log = logging.getLogger(__name__)

BOPTEST_VERSION = "0.8.0"  # the API version whose description this follows (the envelope, test ids, scenarios)


def envelope(message: str, payload, status: int = 200) -> JSONResponse:
    return JSONResponse({"message": message, "payload": _finite(payload), "status": status}, status_code=status)


def _finite(value):
    """JSON has no NaN: None in its place (a value EnergyPlus does not have)."""
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, dict):
        return {k: _finite(v) for k, v in value.items()}
    if isinstance(value, list):
        return [_finite(v) for v in value]
    return value


async def _json(request: Request, empty_ok: bool = False):
    try:
        raw = await _body(request)
    except InputError as e:
        raise TestError(e.status, str(e)) from None
    if not raw.strip():
        if empty_ok:
            return {}
        raise TestError(400, "the body is empty: send a JSON object (Content-Type: application/json)")
    try:
        return json.loads(raw)
    except (ValueError, UnicodeDecodeError) as e:
        raise TestError(400, f"the body is not valid JSON ({e})") from None


def _fields(body, names: tuple[str, ...]) -> list:
    if not isinstance(body, dict):
        raise TestError(400, f"the body must be a JSON object with {', '.join(names)}")
    missing = [n for n in names if n not in body]
    if missing:
        raise TestError(400, f"the body lacks {', '.join(missing)} (it needs {', '.join(names)})")
    return [body[n] for n in names]


def create_app(registry: Registry, token: str | None = None) -> FastAPI:
    app = FastAPI(title="parallel-eplus: BOPTEST's API over EnergyPlus buildings", docs_url=None, redoc_url=None,
                  openapi_url=None)  # fmt: skip
    if token is not None:
        app.add_middleware(BearerToken, token=token)  # a refusal logged at WARNING, never the token
    if log.isEnabledFor(logging.DEBUG):  # every request with its time (`-v`): a line per step otherwise costs
        app.add_middleware(RequestLog)

    @app.exception_handler(TestError)
    async def refused(request: Request, e: TestError) -> JSONResponse:
        (log.warning if e.status < 500 else log.error)("%s %s: %s", request.method, request.url.path, e.message)
        return envelope(e.message, None, e.status)

    @app.exception_handler(Exception)
    async def failed(request: Request, e: Exception) -> JSONResponse:  # a bug of ours: still BOPTEST's envelope
        log.exception("%s %s failed", request.method, request.url.path)
        return envelope(f"{type(e).__name__}: {e}", None, 500)

    @app.on_event("shutdown")
    def shutdown() -> None:
        registry.close()

    async def call(testid: str, method: str, *args, message: str | None = None):
        text, payload = await run_in_threadpool(registry.call, testid, method, *args)
        return envelope(message or text, payload)

    @app.get("/version")
    def version():
        return envelope("Queried the version number successfully.", {"version": BOPTEST_VERSION})

    @app.get("/testcases")
    def testcases():
        return JSONResponse([{"testcaseid": name} for name in registry.testcases])

    @app.post("/testcases/{testcase}/select")
    async def select(testcase: str, request: Request):
        options = await _json(request, empty_ok=True)
        if not isinstance(options, dict):
            raise TestError(400, "the body must be a JSON object (options: weather) or empty")
        testid = await run_in_threadpool(registry.select, testcase, options)
        return JSONResponse({"testid": testid})

    @app.get("/status/{testid}")
    def status(testid: str):
        return PlainTextResponse(registry.status(testid))

    @app.put("/stop/{testid}")
    async def stop(testid: str):
        await run_in_threadpool(registry.stop, testid)
        return PlainTextResponse("OK")

    @app.get("/name/{testid}")
    async def name(testid: str):
        return await call(testid, "name")

    @app.get("/inputs/{testid}")
    async def inputs(testid: str):
        return await call(testid, "inputs")

    @app.get("/measurements/{testid}")
    async def measurements(testid: str):
        return await call(testid, "measurements")

    @app.get("/forecast_points/{testid}")
    async def forecast_points(testid: str):
        return await call(testid, "forecast_points")

    @app.get("/step/{testid}")
    async def get_step(testid: str):
        return await call(testid, "get_step")

    @app.put("/step/{testid}")
    async def set_step(testid: str, request: Request):
        (step,) = _fields(await _json(request), ("step",))
        return await call(testid, "set_step", step)

    @app.get("/scenario/{testid}")
    async def get_scenario(testid: str):
        return await call(testid, "get_scenario")

    @app.put("/scenario/{testid}")
    async def set_scenario(testid: str, request: Request):
        return await call(testid, "set_scenario", await _json(request))

    @app.put("/initialize/{testid}")
    async def initialize(testid: str, request: Request):
        start, warmup = _fields(await _json(request), ("start_time", "warmup_period"))
        return await call(testid, "initialize", start, warmup)

    @app.post("/advance/{testid}")
    async def advance(testid: str, request: Request):
        return await call(testid, "advance", await _json(request, empty_ok=True))

    @app.put("/forecast/{testid}")
    async def forecast(testid: str, request: Request):
        return await call(testid, "forecast", *_fields(await _json(request), ("point_names", "horizon", "interval")))

    @app.put("/results/{testid}")
    async def results(testid: str, request: Request):
        names = ("point_names", "start_time", "final_time")
        return await call(testid, "results_query", *_fields(await _json(request), names))

    @app.get("/kpi/{testid}")
    async def kpi(testid: str):
        return await call(testid, "kpi")

    return app


def serve(testcases: dict[str, Path], host: str = "127.0.0.1", port: int = 8000, token_file: Path | None = None,
          workers: int = 2, idle_timeout_s: float = 900.0, ray_address: str | None = None,
          cache: Path | None = None) -> None:  # fmt: skip
    """Serve BOPTEST's API until Ctrl-C or SIGTERM; every test's processes and files are gone when it returns."""
    import uvicorn

    token = check_access(host, token_file, tls=False)
    remote = None
    if ray_address:
        from parallel_eplus.deploy.boptest.remote import ray_tests

        remote = ray_tests(ray_address, workers)
    registry = Registry(testcases, workers, idle_timeout_s, cache=cache, remote=remote)
    app = create_app(registry, token)
    log.info("BOPTEST API on http://%s:%d: %d test cases (%s), %d workers%s, idle timeout %g s%s", host, port,
             len(testcases), ", ".join(testcases), workers, f" on Ray at {ray_address}" if ray_address else "",
             idle_timeout_s, "; bearer token required" if token else "")  # fmt: skip
    try:
        # a client's connection kept alive through a minute of its own computing between steps (uvicorn's default: 5 s)
        uvicorn.run(app, host=host, port=port, access_log=False, log_level="warning", timeout_graceful_shutdown=3,
                    timeout_keep_alive=60)  # fmt: skip
    finally:
        registry.close()
