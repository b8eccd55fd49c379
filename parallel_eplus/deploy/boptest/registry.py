"""The test cases this server offers and the tests it runs: at most `workers` tests hold an EnergyPlus process at
once (Running), the rest wait in order (Queued); a request that needs the simulation of a queued test waits for its
turn (up to `queue_wait_s`). A test idle past `idle_timeout_s` is stopped, as `PUT /stop` stops one: its process
ended and its pipes and episode folder removed at once. Test ids are random UUIDs (122 bits from the OS's
generator): knowing one test's id tells nothing of another's. A queued test holds nothing to free: its idle time
counts from when it runs.
"""

from __future__ import annotations

import logging
import threading
import time
import uuid
from collections import OrderedDict, deque
from dataclasses import dataclass, field
from pathlib import Path

from parallel_eplus.deploy.boptest.test import BoptestTest, TestError

log = logging.getLogger(__name__)

QUEUED, RUNNING = "Queued", "Running"
FORGET_AFTER = 10_000  # stopped test ids remembered (to say why they are gone)
METADATA = frozenset({"name", "inputs", "measurements", "forecast_points", "get_step", "get_scenario"})


def testcases_of(specs: Path | None = None) -> dict[str, Path]:
    """Every shipped building, then each spec in `specs` (a folder of `.toml` files; its names win), by name."""
    from parallel_eplus.buildings.resources import builtin_specs

    out = dict(builtin_specs())
    if specs is not None:
        found = sorted(Path(specs).expanduser().glob("*.toml"))
        if not found:
            raise FileNotFoundError(f"--specs {specs}: no .toml building spec in it")
        out |= {p.stem: p.resolve() for p in found}
    return out


@dataclass
class Entry:
    testid: str
    testcase: str
    local: BoptestTest  # metadata, and the simulation itself unless tests run on Ray
    runner: object = None  # what runs the episode once Running: `local`, or a Ray actor's proxy (remote.py)
    status: str = QUEUED
    last: float = field(default_factory=time.monotonic)
    busy: int = 0
    lock: threading.Lock = field(default_factory=threading.Lock)


class Registry:
    def __init__(self, testcases: dict[str, Path], workers: int = 2, idle_timeout_s: float = 900.0,
                 queue_wait_s: float = 600.0, cache: Path | None = None, remote=None):  # fmt: skip
        """`remote`: a factory making a Ray actor's proxy for a test's simulation (remote.py); None: in process."""
        if workers < 1:
            raise ValueError(f"--workers {workers}: at least 1")
        if idle_timeout_s <= 0:
            raise ValueError(f"--idle-timeout {idle_timeout_s}: a positive number of seconds")
        self.testcases, self.workers, self.idle_timeout_s = testcases, workers, idle_timeout_s
        self.queue_wait_s, self.cache, self.remote = queue_wait_s, cache, remote
        self.tests: dict[str, Entry] = {}
        self.queue: deque[str] = deque()
        self.stopped: OrderedDict[str, str] = OrderedDict()
        self._cond = threading.Condition()
        self._closing = threading.Event()
        self._reaper = threading.Thread(target=self._reap_loop, name="boptest-idle", daemon=True)
        self._reaper.start()

    # -- selection and lifetime --------------------------------------------------------------------
    def select(self, testcase: str, options: dict) -> str:
        if testcase not in self.testcases:
            raise TestError(404, f"Test case {testcase!r} not found: the test cases are {sorted(self.testcases)}")
        unknown = sorted(set(options) - {"weather"})
        if unknown:
            raise TestError(400, f"unknown selection option(s) {unknown}: the only one is weather (a name of the "
                                 "building's [weathers], a weather code or an .epw path)")  # fmt: skip
        local = BoptestTest(testcase, self.testcases[testcase], options.get("weather"), self.cache)
        entry = Entry(uuid.uuid4().hex, testcase, local)
        with self._cond:
            self.tests[entry.testid] = entry
            self.queue.append(entry.testid)
            self._promote()
        log.info("test %s of %s: %s", entry.testid, testcase, entry.status)
        return entry.testid

    def _promote(self) -> None:
        """Queued tests become Running, in order, while workers are free (holding the condition)."""
        running = sum(e.status == RUNNING for e in self.tests.values())
        while self.queue and running < self.workers:
            entry = self.tests[self.queue.popleft()]
            entry.runner = entry.local if self.remote is None else self.remote(entry)
            entry.status, entry.last = RUNNING, time.monotonic()
            running += 1
        self._cond.notify_all()

    def entry(self, testid: str) -> Entry:
        with self._cond:
            entry = self.tests.get(testid)
            if entry is None:
                why = self.stopped.get(testid)
                raise TestError(404, f"test {testid} {why}; select a test case again" if why else
                                f"no test {testid}: POST /testcases/{{name}}/select gives a testid")  # fmt: skip
            entry.last = time.monotonic()
            return entry

    def status(self, testid: str) -> str:
        return self.entry(testid).status

    def call(self, testid: str, method: str, *args):
        """`method` of the test's simulation, one request at a time per test; a queued test's metadata at once, its
        simulation once it runs."""
        entry = self.entry(testid)
        if entry.status == QUEUED and method in METADATA:
            return getattr(entry.local, method)(*args)
        with self._cond:
            entry.busy += 1
            ok = self._cond.wait_for(lambda: entry.status != QUEUED or testid not in self.tests, self.queue_wait_s)
        try:
            if testid not in self.tests:
                raise TestError(404, f"test {testid} {self.stopped.get(testid, 'was stopped')}")
            if not ok:
                ahead = list(self.queue).index(testid) if testid in self.queue else 0
                raise TestError(503, f"test {testid} is still Queued after {self.queue_wait_s:.0f} s ({ahead} ahead of "
                                     f"it, {self.workers} workers): wait for GET /status to say Running")  # fmt: skip
            with entry.lock:
                if testid not in self.tests:
                    raise TestError(404, f"test {testid} {self.stopped.get(testid, 'was stopped')}")
                try:
                    return getattr(entry.runner, method)(*args)
                except Exception:
                    if testid in self.tests:
                        raise
                    raise TestError(404, f"test {testid} {self.stopped.get(testid, 'was stopped')} meanwhile") from None
        finally:
            with self._cond:
                entry.busy -= 1
                entry.last = time.monotonic()

    def stop(self, testid: str, why: str = "was stopped (PUT /stop)") -> None:
        """End the test's process and remove its files now, whatever it was doing; its next request is a 404."""
        with self._cond:
            entry = self.tests.pop(testid, None)
            if entry is None:
                self.entry(testid)  # raises, saying why
                return
            if testid in self.queue:
                self.queue.remove(testid)
            self.stopped[testid] = why
            while len(self.stopped) > FORGET_AFTER:
                self.stopped.popitem(last=False)
            self._promote()
        runner = entry.runner or entry.local
        held = entry.lock.acquire(timeout=2.0)  # a step ends within ms; an initialize is not waited for
        try:
            runner.close()  # a request still stepping it gets EnergyPlus's end as an error, answered as stopped
        finally:
            if held:
                entry.lock.release()
            if runner is not entry.local:
                entry.local.close()
        log.info("test %s of %s %s", testid, entry.testcase, why)

    def _reap_loop(self) -> None:
        tick = min(1.0, self.idle_timeout_s / 4)
        while not self._closing.wait(tick):
            now = time.monotonic()
            with self._cond:
                idle = [t for t, e in self.tests.items()
                        if e.status == RUNNING and not e.busy and now - e.last > self.idle_timeout_s]  # fmt: skip
            for testid in idle:
                try:
                    self.stop(testid, f"was stopped after {self.idle_timeout_s:g} s without a request (--idle-timeout)")
                except TestError:  # stopped meanwhile
                    pass
                except Exception:  # noqa: BLE001 - one failing close must not end the reaper
                    log.exception("stopping idle test %s", testid)

    def close(self) -> None:
        """Stop every test (the server's end)."""
        self._closing.set()
        for testid in list(self.tests):
            try:
                self.stop(testid, "was stopped: the server shut down")
            except Exception:  # noqa: BLE001 - the others' processes must end too
                log.exception("stopping test %s", testid)
