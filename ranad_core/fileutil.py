"""Atomic output: write to a temporary name in the target folder, rename on success.

A render farm kills jobs at any moment; a half-written EXR that looks complete is worse than none, so every
writer in ranad goes through :func:`atomic_output`.
"""

from __future__ import annotations

import contextlib
import errno
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


#: the errors of a write the machine refused (the disk, the file system, the target), as libraries quote them
WRITE_ERRNOS = (errno.ENOSPC, errno.EDQUOT, errno.EROFS, errno.EFBIG, errno.EACCES, errno.EPERM)
TMP_EXTRA = 16   # what atomic_output's temporary name adds to the output's ("." + 8 random + ".tmp" + ...)


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
    try:
        name_max = os.pathconf(folder, "PC_NAME_MAX")
    except (OSError, ValueError, AttributeError):
        name_max = 255
    if len(os.fsencode(os.path.basename(path))) > name_max:
        raise RanadError(f"file name longer than the {name_max} bytes the output folder allows", path)
    return path


def probe_writable(folder: str) -> None:
    """Create and remove a file in `folder` (RanadError naming it when that fails): what a long job checks
    before its work, since permission bits are not the whole story (root, immutable or read-only mounts)."""
    try:
        fd, probe = tempfile.mkstemp(prefix=".ranad-probe.", dir=folder)
        os.close(fd)
        os.unlink(probe)
    except OSError as e:
        raise RanadError(f"cannot write in this folder ({e.strerror or e})", folder) from None


class Terminated(BaseException):
    """SIGTERM (what a farm sends a job it stops), raised in the main thread so that every `atomic_output` block
    on the way out removes its temporary file (the default action ends the process on the spot)."""


def _tmp_prefix(path: str) -> str:
    """The temporary's name before mkstemp's random part: the output's name, cut so that the whole temporary
    name stays within a folder's 255-byte limit."""
    name = os.path.basename(path)
    while len(os.fsencode(name)) > 255 - TMP_EXTRA - len(os.fsencode(os.path.splitext(path)[1])) - 8:
        name = name[:-1]
    return "." + name + "."


def _write_error(e: BaseException, folder: str) -> str | None:
    """The one-line problem of a failed write (disk full, a file system gone read-only, a protected target),
    or None for an exception that is no writing trouble. Libraries that write for us report a full disk in their
    own ways (safetensors, torch.save: not OSError), so a full folder is looked at directly."""
    if isinstance(e, OSError) and e.errno is not None:
        return f"cannot write ({e.strerror or e})"
    text = str(e)
    for code in WRITE_ERRNOS:   # safetensors, torch.save and OIIO put the system's message in their own
        if os.strerror(code) in text:
            return f"cannot write ({os.strerror(code)})"
    return "cannot write (no space left on device)" if free_bytes(folder) == 0 else None


def free_bytes(folder: str) -> int | None:
    """Bytes an unprivileged write may still put in `folder`'s file system (None where that cannot be asked)."""
    try:
        st = os.statvfs(folder)
    except (OSError, AttributeError):
        return None
    return st.f_bavail * st.f_frsize


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
    target = os.path.abspath(path)   # what the checks saw ("missing/../x.exr" is x.exr, as abspath says)
    folder = os.path.dirname(target)
    if suffix is None:
        suffix = os.path.splitext(path)[1]
    try:  # the permission bits are not the whole story (root, read-only or special file systems, ACLs)
        fd, tmp = tempfile.mkstemp(prefix=_tmp_prefix(path), suffix=".tmp" + suffix, dir=folder)
    except OSError as e:
        raise RanadError(f"cannot write in the output folder ({e.strerror or e})", path) from None
    try:
        os.close(fd)
        yield tmp
        os.chmod(tmp, new_file_mode())       # mkstemp makes 0600 files: give the mode a plain open() would
        _fsync_file(tmp)                     # the data is on disk before the name points at it
        os.replace(tmp, target)
        _fsync_dir(folder)                   # and the rename itself survives a power cut
    except BaseException as e:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        problem = None if isinstance(e, (RanadError, KeyboardInterrupt, Terminated, SystemExit)) else \
            _write_error(e, folder)
        if problem is not None:   # disk full, read-only, protected: one line naming the output, not the temporary
            raise RanadError(problem, path) from None
        raise
