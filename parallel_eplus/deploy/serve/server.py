"""`parallel-eplus serve DIR`: an exported controller over HTTP (FastAPI on uvicorn, onnxruntime; no torch).

`POST /act` takes `{"time": ISO, "sensors": {name: value or {"value", "unit"}}}` in physical units (a planner also
`last_setpoints` and `forecast`: planner_runtime.py) and answers `{"setpoints": {name: {"value", "unit"}}, ...}`;
`GET /health`, `GET /contract`. A bad request is a 4xx whose JSON names the field (`{"error", "field"}`), never a
crash; every request is logged with its status and time, never with its token (`--token-file`: `BearerToken`).
"""

from __future__ import annotations

import hmac
import json
import logging
import sys
import time
from pathlib import Path

import onnxruntime  # noqa: F401 - loaded here, not on the first request
from fastapi import FastAPI, Request
from fastapi.responses import JSONResponse

from parallel_eplus.deploy.serve.contract import InputError
from parallel_eplus.deploy.serve.runtime import load_runtime

log = logging.getLogger("parallel_eplus.deploy.serve.server")

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


class BearerToken:
    """Every request must carry `Authorization: Bearer <token>` (the scheme in any case, RFC 7235; the token
    compared in constant time); anything else is a 401 that names the header. The token is never logged (RequestLog
    logs method, path, status and time only)."""

    def __init__(self, app, token: str):
        self.app, self.expected = app, token.encode()

    async def __call__(self, scope, receive, send):
        if scope["type"] != "http":
            return await self.app(scope, receive, send)
        given = dict(scope.get("headers") or []).get(b"authorization", b"")
        scheme, _, credential = given.strip().partition(b" ")
        bearer = scheme.lower() == b"bearer"
        if hmac.compare_digest(credential.strip() if bearer else b"", self.expected) and bearer:
            return await self.app(scope, receive, send)
        field = "authorization: " + ("missing" if not given else "wrong token" if bearer else "not a Bearer token")
        log.warning("refused %s %s: %s", scope.get("method"), scope.get("path"), field)
        response = JSONResponse({"error": f"{field}; send Authorization: Bearer <token>", "field": "authorization"},
                                status_code=401, headers={"WWW-Authenticate": "Bearer"})  # fmt: skip
        await response(scope, receive, send)


def create_app(directory: Path, token: str | None = None) -> FastAPI:
    """The app for one exported controller (a policy or a planner), its files checked against the contract's
    hashes; with `token`, every request must carry it."""
    directory = Path(directory)
    runtime = load_runtime(directory)
    contract = runtime.contract
    app = FastAPI(title=f"parallel-eplus controller: {contract.data['building']['name']}", docs_url=None)
    if token is not None:
        app.add_middleware(BearerToken, token=token)
    app.add_middleware(RequestLog)  # added last, so outermost: a request refused for its token is logged too
    started = time.time()
    served = {"act": 0, "refused": 0, "fallback": 0}

    @app.get("/health")
    def health() -> dict:
        return {
            "status": "ok", "building": contract.data["building"]["name"], "run": contract.data["policy"]["run"],
            "kind": contract.data.get("kind", "policy"), "uptime_s": round(time.time() - started, 1), **served,
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
                raise InputError("content-type", f"{kind or 'none'}; send application/json", 415)
            raw = await _body(request)
            try:
                body = json.loads(raw)
            except (ValueError, UnicodeDecodeError) as e:
                raise InputError("body", f"not valid JSON ({e})", 400) from None
            if not isinstance(body, dict):
                raise InputError("body", "must be a JSON object with 'sensors' (and 'time')", 400)
            answer = runtime.act(body)
        except InputError as e:
            served["refused"] += 1
            log.warning("refused: %s", e)
            return _error(e.status, e.field, str(e))
        served["act"] += 1
        served["fallback"] += bool(answer.get("fallback"))
        return JSONResponse(answer)

    return app


LOOPBACK = ("127.0.0.1", "localhost", "::1")
MIN_TOKEN_CHARS = 16  # `secrets.token_urlsafe(32)` gives 43


def loopback(host: str) -> bool:
    return host in LOOPBACK or host.startswith("127.")


def read_token(path: Path | None) -> str | None:
    """The bearer token in `path` (its first line), or None. Refused, with the reason: an empty file, a token
    shorter than MIN_TOKEN_CHARS, a file that others than its owner may read or write (as ssh refuses a key)."""
    if path is None:
        return None
    lines = Path(path).read_text().strip().splitlines()
    token = lines[0].strip() if lines else ""
    if not token:
        raise ValueError(f"--token-file {path} is empty: put the token on its first line")
    if len(token) < MIN_TOKEN_CHARS:
        raise ValueError(
            f"--token-file {path}: the token has {len(token)} characters; at least {MIN_TOKEN_CHARS} are needed "
            "(`python -c 'import secrets; print(secrets.token_urlsafe(32))'` makes one)"
        )
    mode = Path(path).stat().st_mode & 0o777
    if mode & 0o077:
        raise ValueError(f"--token-file {path} may be read or written by others than its owner (mode {mode:o}): "
                         f"chmod 600 {path}")  # fmt: skip
    return token


def check_access(host: str, token_file: Path | None, tls: bool) -> str | None:
    """The token `serve` requires (None: none), refusing what would expose the controller (off loopback without a
    token; a weak or exposed token file: `read_token`) and warning, loudly, of a token sent in clear (plain HTTP
    off loopback)."""
    if not loopback(host) and token_file is None:
        raise ValueError(
            f"--host {host} lets other machines reach the controller: give --token-file FILE (a secret on its first "
            "line; clients send Authorization: Bearer <it>), and --ssl-keyfile/--ssl-certfile for TLS"
        )
    token = read_token(token_file)
    if not loopback(host) and not tls:
        log.warning("PLAIN HTTP on %s: the bearer token and every reading cross the network in clear, readable by "
                    "anyone on the path; give --ssl-keyfile and --ssl-certfile (TLS), or serve on 127.0.0.1 behind "
                    "a TLS proxy", host)  # fmt: skip
    return token


def serve(directory: Path, host: str = "127.0.0.1", port: int = 8000, token_file: Path | None = None,
          ssl_keyfile: Path | None = None, ssl_certfile: Path | None = None) -> None:  # fmt: skip
    """Run the controller's server until Ctrl-C or SIGTERM. Off loopback it needs a token (`token_file`)."""
    import uvicorn

    if (ssl_keyfile is None) != (ssl_certfile is None):
        raise ValueError("TLS needs both --ssl-keyfile and --ssl-certfile")
    app = create_app(directory, check_access(host, token_file, ssl_certfile is not None))
    scheme = "https" if ssl_certfile else "http"
    log.info("serving %s on %s://%s:%d (POST /act, GET /health, GET /contract%s)", directory, scheme, host, port,
             "; bearer token required" if token_file else "")  # fmt: skip
    # SIGTERM stops it within seconds even with a client's connection left open (uvicorn waits for them otherwise)
    uvicorn.run(app, host=host, port=port, access_log=False, log_level="warning", timeout_graceful_shutdown=3,
                ssl_keyfile=None if ssl_keyfile is None else str(ssl_keyfile),
                ssl_certfile=None if ssl_certfile is None else str(ssl_certfile))  # fmt: skip
