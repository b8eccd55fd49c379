"""The C half of the EnergyPlus-side bridge (`eplus_callback.c`): compiled on first use, cached per source.

Why C: once a run is under way, every control step costs EnergyPlus two Python callbacks (plus one per
HVAC sub-timestep), ten actuator writes and a pipe exchange; in C the step's own cost falls from tens
of microseconds to a few. Where the bridge cannot be built or loaded, the Python bridge does the same
exchange (slower), and a warning says so once.
"""

from __future__ import annotations

import ctypes
import functools
import hashlib
import logging
import os
import platform
import shlex
import shutil
import stat
import subprocess
import tempfile
from pathlib import Path

log = logging.getLogger(__name__)

SOURCE = Path(__file__).with_name("eplus_callback.c")
FLAGS = ["-O2", "-shared", "-fPIC"]


def _cache_dirs() -> list[Path]:
    """The user's cache, then a private directory under /tmp (for a read-only or missing home)."""
    dirs = []
    base = os.environ.get("XDG_CACHE_HOME") or (os.environ.get("HOME") and Path(os.environ["HOME"]) / ".cache")
    if base:
        dirs.append(Path(base) / "parallel-eplus")
    dirs.append(Path(tempfile.gettempdir()) / f"parallel_eplus_native_{os.getuid()}")
    return dirs


def _ours(directory: Path) -> bool:
    """Only a directory this user owns and nobody else can write to may hold a library we load."""
    st = directory.stat()
    return st.st_uid == os.getuid() and not st.st_mode & (stat.S_IWGRP | stat.S_IWOTH)


def _loads(lib: Path) -> bool:
    try:
        ctypes.CDLL(str(lib))  # what the EnergyPlus process will do: fail here, not in every episode
        return True
    except OSError as e:
        log.warning("the C bridge %s does not load (%s)", lib, e)
        return False


@functools.cache
def bridge_library() -> str | None:
    """Path of the compiled bridge, or None (warned once) if it cannot be built or loaded here."""
    cc = shlex.split(os.environ.get("CC", "")) or [shutil.which("cc") or shutil.which("gcc") or "cc"]
    tag = hashlib.sha256(SOURCE.read_bytes() + " ".join([platform.machine(), *FLAGS]).encode()).hexdigest()[:16]
    for cache in _cache_dirs():
        lib = cache / f"eplus_callback-{tag}.so"
        try:
            cache.mkdir(mode=0o700, parents=True, exist_ok=True)
            if not _ours(cache):
                continue
            if not lib.is_file():
                if not os.access(cache, os.W_OK):
                    continue
                tmp = lib.with_name(f"{lib.name}.{os.getpid()}.tmp")
                subprocess.run(
                    [*cc, *FLAGS, "-o", str(tmp), str(SOURCE)], check=True, capture_output=True, text=True, timeout=120
                )
                os.replace(tmp, lib)  # atomic: processes compiling at once each install a whole library
        except PermissionError:
            continue  # a read-only cache: try the next place
        except FileNotFoundError:
            log.warning("no C compiler found (set CC); the Python bridge steps EnergyPlus instead (slower per step)")
            return None
        except (OSError, subprocess.SubprocessError) as e:
            detail = (getattr(e, "stderr", "") or str(e)).strip()
            log.warning("the C bridge did not compile (%s); the Python bridge steps EnergyPlus instead", detail)
            return None
        if _loads(lib):
            return str(lib)
    log.warning("the C bridge cannot be built or loaded here; the Python bridge steps EnergyPlus instead")
    return None


def register(api, state, bridge, native: str | None) -> list:
    """Register the callbacks: the Bridge's own, or the C ones that call it until it arms them.

    Returns what must stay alive while EnergyPlus runs (ctypes callback objects)."""
    rt = api.runtime
    if native is None:
        if bridge.before_predictor:  # bridge.py's apply point
            rt.callback_begin_system_timestep_before_predictor(state, bridge.apply_action)
        else:
            rt.callback_after_predictor_after_hvac_managers(state, bridge.apply_action)
        rt.callback_end_zone_timestep_after_zone_reporting(state, bridge.observe)
        return []
    lib = ctypes.CDLL(native)
    lib.bridge_init.argtypes = [ctypes.c_void_p] * 12
    lib.bridge_init.restype = None
    ints, doubles = ctypes.POINTER(ctypes.c_int), ctypes.POINTER(ctypes.c_double)
    lib.bridge_hold.argtypes = [ctypes.c_int, ints, ctypes.c_int, ints, ints, ctypes.c_int, doubles, ctypes.c_int,
                                doubles]  # fmt: skip
    lib.bridge_unhold.argtypes = [doubles]
    lib.bridge_arm.argtypes = [
        ctypes.c_int, ctypes.c_int, ctypes.c_int, ctypes.POINTER(ctypes.c_int), ctypes.c_int,
        ctypes.POINTER(ctypes.c_int), ctypes.POINTER(ctypes.c_int), ctypes.c_int,
        ctypes.POINTER(ctypes.c_double), ctypes.c_int, ctypes.c_long, ctypes.c_long, ctypes.c_int, ctypes.c_double,
        ctypes.POINTER(ctypes.c_double), ctypes.c_long, ctypes.c_long,
    ]  # fmt: skip
    lib.bridge_step.restype = ctypes.c_long
    lib.bridge_done_at.restype = ctypes.c_double
    lib.bridge_wait_s.restype = lib.bridge_ahead_s.restype = ctypes.c_double
    for name in ("bridge_exchanges", "bridge_apply_calls", "bridge_observe_calls"):
        getattr(lib, name).restype = ctypes.c_long
    lib.bridge_error.restype = ctypes.c_char_p
    callback = rt.py_state_callback_type  # void *(*)(void *state), as EnergyPlus calls it
    slow = [callback(bridge.apply_action), callback(bridge.observe)]
    x, r = api.exchange.api, rt.api
    functions = [x.getVariableValue, x.setActuatorValue, x.calendarYear, x.dayOfYear, x.hour, x.zoneTimeStepNum,
                 r.stopSimulation, x.warmupFlag, x.kindOfSim, x.apiDataFullyReady]  # fmt: skip
    lib.bridge_init(*(ctypes.cast(f, ctypes.c_void_p) for f in [*slow, *functions]))
    fast = [callback(("bridge_apply_action", lib)), callback(("bridge_observe", lib))]
    if bridge.before_predictor:
        r.callbackBeginTimeStepBeforePredictor(state, fast[0])
    else:
        r.callbackAfterPredictorAfterHVACManagers(state, fast[0])
    r.callbackEndOfZoneTimeStepAfterZoneReporting(state, fast[1])
    bridge.native = lib
    return [lib, *slow, *fast]
