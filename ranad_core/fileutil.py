"""Atomic output: write to a temporary name in the target folder, rename on success.

A render farm kills jobs at any moment; a half-written EXR that looks complete is worse than none, so every
writer in ranad goes through :func:`atomic_output`.
"""

from __future__ import annotations

import contextlib
import os
import tempfile
from typing import Iterator

from .errors import RanadError


def not_a_file(path: str) -> RanadError:
    """The error for an input path that is not a regular file: a folder, a pipe or device, or nothing at all."""
    if os.path.isdir(path):
        return RanadError("is a directory, expected a file", path)
    if os.path.exists(path):
        return RanadError("not a regular file (a pipe or device?), expected a file", path)
    return RanadError("no such file", path)


def check_writable_target(path: str | os.PathLike) -> str:
    """Fail early (before any work) if ``path`` cannot be created; returns it as a string."""
    path = os.fspath(path)
    folder = os.path.dirname(os.path.abspath(path))
    if os.path.isdir(path):
        raise RanadError("is a directory, expected a file name", path)
    if not os.path.isdir(folder):
        raise RanadError("output folder does not exist", path)
    if not os.access(folder, os.W_OK):
        raise RanadError("output folder is not writable", path)
    return path


def new_file_mode() -> int:
    """The mode a file created now gets from the process umask (0o666 & ~umask), as open() would give it."""
    mask = os.umask(0o022)
    os.umask(mask)
    return 0o666 & ~mask


def _fsync_file(path: str) -> None:
    with open(path, "rb") as f:
        os.fsync(f.fileno())


def _fsync_dir(folder: str) -> None:
    with contextlib.suppress(OSError):  # not every file system lets a folder be opened and synced
        fd = os.open(folder, os.O_RDONLY)
        try:
            os.fsync(fd)
        finally:
            os.close(fd)


@contextlib.contextmanager
def atomic_output(path: str | os.PathLike, suffix: str | None = None) -> Iterator[str]:
    """Yield a temporary path next to ``path``; rename it onto ``path`` if the block succeeds.

    The temporary keeps the target's extension (``suffix``) so that libraries choosing a format by
    extension (OpenImageIO) pick the right one. On any exception the temporary is removed.
    """
    path = check_writable_target(path)
    folder = os.path.dirname(os.path.abspath(path))
    if suffix is None:
        suffix = os.path.splitext(path)[1]
    try:  # the permission bits are not the whole story (root, read-only or special file systems, ACLs)
        fd, tmp = tempfile.mkstemp(prefix="." + os.path.basename(path) + ".", suffix=".tmp" + suffix, dir=folder)
    except OSError as e:
        raise RanadError(f"cannot write in the output folder ({e.strerror or e})", path) from None
    os.close(fd)
    try:
        yield tmp
        os.chmod(tmp, new_file_mode())       # mkstemp makes 0600 files: give the mode a plain open() would
        _fsync_file(tmp)                     # the data is on disk before the name points at it
        os.replace(tmp, path)
        _fsync_dir(folder)                   # and the rename itself survives a power cut
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        raise
