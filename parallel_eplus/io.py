"""Atomic writes: a later step reads either the previous version of a file or the new one, never half.

Every file the service writes that something reads back (model, statistics, checkpoints, config.json,
episodes.csv, evaluation results) goes through `atomic_path`: written to a hidden temporary file in the
same directory, flushed to disk, then renamed over the target. A crash or a full disk mid-write leaves
the previous version as it was and no temporary file behind.
"""

from __future__ import annotations

import contextlib
import errno
import os
from collections.abc import Iterator
from pathlib import Path


class DiskFullError(OSError):
    """No space left where a file was being written; the previous version of the file is intact."""


def _tmp_name(target: Path) -> Path:
    # Hidden, and not ending in the target's suffix: no glob for checkpoints (*.zip) or stats matches it.
    return target.with_name(f".{target.name}.tmp-{os.getpid()}")


def _fsync(path: Path) -> None:
    with contextlib.suppress(OSError):  # some filesystems refuse fsync on a read-only descriptor
        fd = os.open(path, os.O_RDONLY)
        try:
            os.fsync(fd)
        finally:
            os.close(fd)


@contextlib.contextmanager
def atomic_path(target: str | os.PathLike) -> Iterator[Path]:
    """A temporary path to write to; on success it replaces `target` in one rename.

    On any error the temporary file is removed and `target` is untouched; a full disk becomes a
    `DiskFullError` naming the file.
    """
    target = Path(target)
    tmp = _tmp_name(target)
    try:
        yield tmp
        _fsync(tmp)
        os.replace(tmp, target)
    except BaseException as e:
        with contextlib.suppress(OSError):
            tmp.unlink()
        if isinstance(e, OSError) and e.errno in (errno.ENOSPC, errno.EDQUOT):
            raise DiskFullError(
                e.errno, f"no space left on the device writing {target}; its previous version is intact"
            ) from e
        raise


def write_bytes(target: str | os.PathLike, data: bytes) -> Path:
    with atomic_path(target) as tmp:
        tmp.write_bytes(data)
    return Path(target)


def write_text(target: str | os.PathLike, text: str) -> Path:
    return write_bytes(target, text.encode())


def append_text(target: str | os.PathLike, text: str) -> Path:
    """Append by rewriting: the old content plus `text`, renamed over the file (files read back here are small)."""
    target = Path(target)
    old = target.read_bytes() if target.is_file() else b""
    return write_bytes(target, old + text.encode())


def remove_stale_temporaries(folder: str | os.PathLike) -> list[Path]:
    """Temporary files in `folder` left by a writer that was killed mid-write (its PID is gone)."""
    removed = []
    for tmp in Path(folder).glob(".*.tmp-*"):
        pid = tmp.name.rsplit("-", 1)[1]
        if pid.isdigit() and not Path(f"/proc/{pid}").exists():
            with contextlib.suppress(OSError):
                tmp.unlink()
                removed.append(tmp)
    return removed
