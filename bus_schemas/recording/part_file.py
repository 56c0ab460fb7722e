"""The ``.part`` file a recording is written to: opened under an exclusive lock (one writer
per recording: a second run given the same path fails at once with
:class:`RecordingInUseError`), and guarded (a failed write, a full disk or a file-size
limit, is kept and raised naming the recording). The recorder renames it to the final name
once the file is complete."""

from __future__ import annotations

import fcntl
import os
from collections.abc import Callable
from pathlib import Path
from typing import Any


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


def locked_part(path: Path, part: Path) -> Any:
    """The ``.part`` file of ``path`` opened for writing under an exclusive lock (released
    when it is closed): a second run given the same recording path fails at once instead of
    writing into the first's file; a part left by a killed run (not locked) is reused."""
    fd = os.open(part, os.O_RDWR | os.O_CREAT, 0o644)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        os.close(fd)
        raise RecordingInUseError(f"{path}: another run is writing this recording (its "
                                  f"{part.name} is locked)") from None
    except BaseException:
        os.close(fd)
        raise
    os.ftruncate(fd, 0)
    return os.fdopen(fd, "wb")

