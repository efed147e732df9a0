"""Atomic file writes, the one implementation for the project (deploy, robot_hoi and sim2sim import it).

Write to a temporary file in the target's folder, then rename over the target: a crash or power cut never leaves a
half-written log, summary or checkpoint where a user expects a good one. With `fsync` the data and the rename are
flushed to the disk before returning (a power cut right after keeps the file), at the cost of waiting for the disk.
It lives in deploy/ because deploy must import without robot_hoi; robot_hoi may depend on deploy, not the other
way round.
"""

from __future__ import annotations

import contextlib
import os
import tempfile
from collections.abc import Iterator
from pathlib import Path


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike, suffix: str | None = None, fsync: bool = False) -> Iterator[Path]:
    """Yield a temporary path next to `path`; on success it replaces `path`, on error it is removed.

    `suffix` defaults to the target's own suffix, so writers that pick a format by extension still work.
    """
    target = Path(path)
    target.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=target.parent, prefix=f".{target.name}.", suffix=suffix or target.suffix)
    os.close(fd)
    os.chmod(tmp, 0o666 & ~_umask())  # mkstemp makes 0600; others (e.g. the robot's user) must read outputs
    tmp_path = Path(tmp)
    try:
        yield tmp_path
        if fsync:
            _fsync(tmp_path, os.O_RDONLY)
        os.replace(tmp_path, target)
        if fsync:
            _fsync(target.parent, os.O_RDONLY | getattr(os, "O_DIRECTORY", 0))  # the rename itself
    except BaseException:
        tmp_path.unlink(missing_ok=True)
        raise


def _fsync(path: Path, flags: int) -> None:
    fd = os.open(path, flags)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def atomic_write_bytes(path: str | os.PathLike, data: bytes, fsync: bool = False) -> None:
    with atomic_path(path, fsync=fsync) as tmp:
        tmp.write_bytes(data)


def atomic_write_text(path: str | os.PathLike, text: str, fsync: bool = False) -> None:
    atomic_write_bytes(path, text.encode(), fsync=fsync)
