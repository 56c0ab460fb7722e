"""The ``.part`` file a recording is written to: created safely, opened under an exclusive
lock (one writer per recording: a second run given the same path fails at once with
:class:`RecordingInUseError`), and guarded (a failed write, a full disk or a file-size
limit, is kept and raised naming the recording). The recorder renames it to the final name
once the file is complete.

Safe in a shared writable folder: the part file is created with ``O_CREAT | O_EXCL |
O_NOFOLLOW``; an existing one is taken over only if it is a stale part of this user (a
regular file, owned by the effective user, one link, not locked: a killed run's); a
symbolic link, another user's file or anything else under the name is refused with
:class:`UnsafePartFileError` and left untouched.  The file gets mode 0o666 less the umask
(:func:`hp_model.atomic_io.output_mode`), which the rename keeps."""

from __future__ import annotations

import errno
import fcntl
import os
import stat
from collections.abc import Callable
from pathlib import Path
from typing import Any

from hp_model.atomic_io import output_mode

_NOFOLLOW = getattr(os, "O_NOFOLLOW", 0)
_CLOEXEC = getattr(os, "O_CLOEXEC", 0)
_CREATE = os.O_RDWR | os.O_CREAT | os.O_EXCL | _NOFOLLOW | _CLOEXEC
# O_NONBLOCK: opening a FIFO or a device planted under the name never blocks (then refused)
_EXISTING = os.O_RDWR | _NOFOLLOW | _CLOEXEC | os.O_NONBLOCK
_REMEDY = "remove it or record elsewhere"


def error_naming(e: OSError, path: Path) -> OSError:
    """``e`` (same class and errno) naming the recording instead of whatever it named."""
    return type(e)(e.errno, e.strerror or str(e), str(path))


class GuardedFile:
    """The recording's part file as the MCAP writer's stream: a failed write (a full disk,
    a file-size limit) is kept in :attr:`error` and raised naming the recording."""

    def __init__(self, f: Any, path: Path) -> None:
        self._f, self._path = f, path
        self.error: OSError | None = None

    def _guard(self, op: Callable[..., Any], *a: Any) -> Any:
        try:
            return op(*a)
        except OSError as e:
            self.error = self.error or e
            raise error_naming(e, self._path) from None

    def write(self, data: Any) -> int:
        return self._guard(self._f.write, data)

    def flush(self) -> None:
        self._guard(self._f.flush)

    def tell(self) -> int:
        return self._f.tell()

    def fileno(self) -> int:
        return self._f.fileno()

    def close(self) -> None:
        self._f.close()


class RecordingInUseError(ValueError):
    """Another process is writing the same recording."""


class UnsafePartFileError(ValueError):
    """The part file's name holds something this run must not write: a symbolic link,
    another user's file, a file with other links, or not a regular file."""


def _check_existing(fd: int, part: Path) -> None:
    """Refuse (closing ``fd``) an existing part that is not a stale part of this user."""
    st = os.fstat(fd)
    why = ("is not a regular file" if not stat.S_ISREG(st.st_mode) else
           f"belongs to another user (uid {st.st_uid})" if st.st_uid != os.geteuid() else
           "has other hard links" if st.st_nlink != 1 else "")
    if why:
        os.close(fd)
        raise UnsafePartFileError(f"{part}: {why}; not writing into it ({_REMEDY})")
    fcntl.fcntl(fd, fcntl.F_SETFL, fcntl.fcntl(fd, fcntl.F_GETFL) & ~os.O_NONBLOCK)


def _open_part(part: Path) -> tuple[int, bool]:
    """``(fd, created)``: a new part file, or an existing one that passes the checks."""
    for _ in range(10):  # a name that comes and goes between the two opens: try again
        try:
            return os.open(part, _CREATE, 0o666), True  # the umask applies
        except FileExistsError:
            pass
        try:
            fd = os.open(part, _EXISTING)
        except FileNotFoundError:
            continue
        except OSError as e:
            if e.errno in (errno.ELOOP, errno.EMLINK):  # O_NOFOLLOW met a symbolic link
                raise UnsafePartFileError(f"{part}: is a symbolic link; a recording is "
                                          f"never written through one ({_REMEDY})") from None
            if e.errno == errno.EISDIR:
                raise UnsafePartFileError(f"{part}: is a folder ({_REMEDY})") from None
            raise
        _check_existing(fd, part)
        return fd, False
    raise UnsafePartFileError(f"{part}: keeps appearing and disappearing ({_REMEDY})")


def same_file(fd: int, path: Path) -> bool:
    """``path`` (not followed) is the file open as ``fd``."""
    try:
        a, b = os.fstat(fd), os.lstat(path)
    except OSError:
        return False
    return (a.st_dev, a.st_ino) == (b.st_dev, b.st_ino)


def locked_part(path: Path, part: Path) -> Any:
    """The ``.part`` file of ``path`` opened for writing under an exclusive lock (released
    when it is closed): a second run given the same recording path fails at once instead of
    writing into the first's file; a part left by a killed run of this user (not locked) is
    reused (emptied, its mode set from the umask); anything else is refused (module doc)."""
    fd, created = _open_part(part)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        os.close(fd)
        raise RecordingInUseError(f"{path}: another run is writing this recording (its "
                                  f"{part.name} is locked)") from None
    except BaseException:
        os.close(fd)
        raise
    try:
        if not created:
            os.ftruncate(fd, 0)
            os.fchmod(fd, output_mode())
    except BaseException:
        os.close(fd)
        raise
    return os.fdopen(fd, "wb")
