"""The C half of the EnergyPlus-side bridge (`eplus_callback.c`): compiled on first use, cached per source.

Why C: once a run is under way, every control step costs EnergyPlus two Python callbacks (plus one per
HVAC sub-timestep), ten actuator writes and a pipe exchange; in C the step's own cost falls from tens
of microseconds to a few. Where no C compiler works the Python bridge does the same exchange (slower),
and a warning says so once.
"""

from __future__ import annotations

import functools
import hashlib
import logging
import os
import platform
import shutil
import subprocess
import tempfile
from pathlib import Path

log = logging.getLogger(__name__)

SOURCE = Path(__file__).with_name("eplus_callback.c")


def _cache_dir() -> Path:
    base = os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache"
    return Path(base) / "parallel-eplus"


@functools.cache
def bridge_library() -> str | None:
    """Path of the compiled bridge, or None (warned once) if it cannot be built here."""
    source = SOURCE.read_bytes()
    tag = hashlib.sha256(source + platform.machine().encode()).hexdigest()[:16]
    cc = os.environ.get("CC") or shutil.which("cc") or shutil.which("gcc")
    for cache in (_cache_dir(), Path(tempfile.gettempdir()) / f"parallel_eplus_native_{os.getuid()}"):
        lib = cache / f"eplus_callback-{tag}.so"
        if lib.is_file():
            return str(lib)
        if cc is None:
            break
        try:
            cache.mkdir(parents=True, exist_ok=True)
            tmp = lib.with_name(f"{lib.name}.{os.getpid()}.tmp")
            subprocess.run(
                [cc, "-O2", "-shared", "-fPIC", "-o", str(tmp), str(SOURCE)],
                check=True, capture_output=True, text=True, timeout=120,
            )  # fmt: skip
            os.replace(tmp, lib)  # atomic: workers compiling at once each install a whole library
            return str(lib)
        except PermissionError:
            continue  # a read-only home: try the temporary directory
        except (OSError, subprocess.SubprocessError) as e:
            detail = getattr(e, "stderr", "") or e
            log.warning("the C bridge did not compile (%s); the Python bridge steps EnergyPlus instead", detail)
            return None
    log.warning("no C compiler found (set CC); the Python bridge steps EnergyPlus instead (slower per step)")
    return None
