"""A controller server in its own process for a test: `parallel-eplus serve DIR` on a free port of loopback."""

from __future__ import annotations

import contextlib
import faulthandler
import io
import json
import logging
import socket
import subprocess
import sys
import time
import urllib.request
from pathlib import Path


def cli(*args: str, timeout_s: float = 300) -> subprocess.CompletedProcess:
    """`parallel-eplus ARGS` in this process (a fresh interpreter pays torch's import each time): its exit code, and
    its log as the command's stderr shows it (a process's own exit code and stderr: tests/faults/test_run_files.py).
    A command that should have refused but runs on (a server that starts) ends the session after `timeout_s`, with
    every thread's traceback, rather than hanging it."""
    from parallel_eplus.cli import main

    stream, root = io.StringIO(), logging.getLogger()
    handler = logging.StreamHandler(stream)
    root.addHandler(handler)
    faulthandler.dump_traceback_later(timeout_s, exit=True)
    try:
        code = main(list(args))
    finally:
        faulthandler.cancel_dump_traceback_later()
        root.removeHandler(handler)
    return subprocess.CompletedProcess(args, code, "", stream.getvalue())


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def get(url: str, headers: dict | None = None, context=None) -> dict:
    request = urllib.request.Request(url, headers=headers or {})
    with urllib.request.urlopen(request, timeout=5, context=context) as r:
        return json.loads(r.read())


@contextlib.contextmanager
def serving(directory: Path, log: Path, *args: str, headers: dict | None = None, scheme: str = "http", context=None):
    """Yields the server's URL; its log goes to `log` (a pipe nobody reads would fill up). Stopped on exit.
    `headers`, `context`: what the readiness probe sends (a token; TLS's certificate)."""
    port = free_port()
    proc = subprocess.Popen(
        [sys.executable, "-m", "parallel_eplus.cli", "serve", str(directory), "--port", str(port), *args],
        stdout=log.open("w"), stderr=subprocess.STDOUT, text=True,
    )  # fmt: skip
    url = f"{scheme}://127.0.0.1:{port}"
    try:
        deadline = time.monotonic() + 60
        while True:
            try:
                get(url + "/health", headers, context)
                break
            except OSError:
                if proc.poll() is not None or time.monotonic() > deadline:
                    raise AssertionError(f"the server did not start: {log.read_text()}") from None
                time.sleep(0.2)
        yield url
    finally:
        proc.terminate()
        proc.wait(timeout=30)
