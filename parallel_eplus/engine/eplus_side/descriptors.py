"""After a fork, parent and child share each open file's description, its offset included: a child that writes
would move its parent's. Each kind of child (an episode forked from a template, fork.py; a branch of a running
episode, branch.py) gives itself descriptions of its own first, and says where its outputs go."""

from __future__ import annotations

import contextlib
import fcntl
import os
import shutil
import stat
from collections.abc import Callable
from pathlib import Path


def own_descriptions(output: Callable[[Path, int], int]) -> None:
    """Every descriptor open on a regular file gets a file description of its own, at the same offset: an input is
    reopened read-only; an output is what `output(path, flags)` opens (a new descriptor, or an OSError)."""
    for name in os.listdir("/proc/self/fd"):
        fd = int(name)
        if fd <= 2:
            continue
        try:
            target = Path(os.readlink(f"/proc/self/fd/{fd}"))
            if not stat.S_ISREG(os.fstat(fd).st_mode):
                continue
        except OSError:  # the listing's own descriptor, closed by now
            continue
        flags = fcntl.fcntl(fd, fcntl.F_GETFL)
        offset = os.lseek(fd, 0, os.SEEK_CUR)
        new = os.open(target, os.O_RDONLY) if flags & os.O_ACCMODE == os.O_RDONLY else output(target, flags)
        with contextlib.suppress(OSError):  # /dev/null ignores its offset
            os.lseek(new, offset, os.SEEK_SET)
        os.dup2(new, fd)
        os.close(new)


def reopened_copy(target: Path, folder: Path, flags: int) -> int:
    """`target` copied into `folder` and opened there as it was opened (its access mode, append or not)."""
    shutil.copyfile(target, folder / target.name)
    return os.open(folder / target.name, (flags & os.O_ACCMODE) | (flags & os.O_APPEND))
