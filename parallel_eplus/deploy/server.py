"""`parallel-eplus serve DIR`: an exported controller over HTTP (FastAPI on uvicorn, onnxruntime; no torch).

`POST /act` takes `{"time": ISO, "sensors": {name: value or {"value", "unit"}}}` in physical units and answers
`{"setpoints": {name: {"value", "unit"}}, ...}`; `GET /health`, `GET /contract`. A bad request is a 4xx whose
JSON names the field (`{"error", "field"}`), never a crash; every request is logged with its status and time.
"""

from __future__ import annotations

import json
import logging
import sys
import time
from pathlib import Path

import numpy as np
import onnxruntime  # noqa: F401 - loaded here, not on the first request
from fastapi import FastAPI, Request
from fastapi.responses import JSONResponse

from parallel_eplus.deploy.contract import Contract, InputError, load_session

log = logging.getLogger("parallel_eplus.deploy.server")

MAX_BODY_BYTES = 64 * 1024  # a request names a few dozen readings: anything near this is not one


def _error(status: int, field: str, message: str) -> JSONResponse:
    return JSONResponse({"error": message, "field": field}, status_code=status)


async def _body(request: Request) -> bytes:
    """The body, read no further than MAX_BODY_BYTES (a lying or absent Content-Length changes nothing)."""
    declared = request.headers.get("content-length")
    if declared is not None and declared.isdigit() and int(declared) > MAX_BODY_BYTES:
        raise InputError("body", f"{declared} bytes; at most {MAX_BODY_BYTES}", 413)
    chunks, size = [], 0
    async for chunk in request.stream():
        size += len(chunk)
        if size > MAX_BODY_BYTES:
            raise InputError("body", f"over {MAX_BODY_BYTES} bytes", 413)
        chunks.append(chunk)
    return b"".join(chunks)


class RequestLog:
    """Logs every request with its status and time (plain ASGI: FastAPI's `@app.middleware` costs more per call)."""

    def __init__(self, app):
        self.app = app

    async def __call__(self, scope, receive, send):
        if scope["type"] != "http":
            return await self.app(scope, receive, send)
        t0, status = time.perf_counter(), [500]

        async def sending(message):
            if message["type"] == "http.response.start":
                status[0] = message["status"]
            await send(message)

        try:
            await self.app(scope, receive, sending)
        finally:
            ms = (time.perf_counter() - t0) * 1000
            log.info("%s %s %d %.2f ms", scope["method"], scope["path"], status[0], ms)


def create_app(directory: Path) -> FastAPI:
    """The app for one exported controller; the ONNX file is checked against its contract's hash."""
    directory = Path(directory)
    contract = Contract.read(directory)
    session, io_names = load_session(directory, contract)
    app = FastAPI(title=f"parallel-eplus controller: {contract.data['building']['name']}", docs_url=None)
    app.add_middleware(RequestLog)
    started = time.time()
    served = {"act": 0, "refused": 0}

    @app.get("/health")
    def health() -> dict:
        return {
            "status": "ok", "building": contract.data["building"]["name"], "run": contract.data["policy"]["run"],
            "uptime_s": round(time.time() - started, 1), **served,
            "loaded": {m: m in sys.modules for m in ("onnxruntime", "torch", "stable_baselines3")},
        }  # fmt: skip

    @app.get("/contract")
    def get_contract() -> dict:
        return contract.data

    @app.post("/act")
    async def act(request: Request) -> JSONResponse:
        try:
            kind = request.headers.get("content-type", "").split(";")[0].strip().lower()
            if kind != "application/json":
                served["refused"] += 1
                return _error(415, "content-type", f"{kind or 'none'}; send application/json")
            raw = await _body(request)
            try:
                body = json.loads(raw)
            except (ValueError, UnicodeDecodeError) as e:
                raise InputError("body", f"not valid JSON ({e})", 400) from None
            obs = contract.observation(body)
        except InputError as e:
            served["refused"] += 1
            log.warning("refused: %s", e)
            return _error(e.status, e.field, str(e))
        row = session.run([io_names[1]], {io_names[0]: obs})[0][0]
        if not np.all(np.isfinite(row)):  # pragma: no cover - the graph clips every value it is given
            return _error(500, "setpoints", "the controller produced a non-finite setpoint")
        served["act"] += 1
        return JSONResponse({"setpoints": contract.setpoints(row), "time": body.get("time")})

    return app


def serve(directory: Path, host: str = "127.0.0.1", port: int = 8000) -> None:
    """Run the controller's server until Ctrl-C or SIGTERM."""
    import uvicorn

    app = create_app(directory)
    log.info("serving %s on http://%s:%d (POST /act, GET /health, GET /contract)", directory, host, port)
    uvicorn.run(app, host=host, port=port, access_log=False, log_level="warning")
