"""Atomic file output: a temporary file in the target folder, then ``os.replace``.

A failed or interrupted write never leaves a partial file under the target name, nor the
temporary one; an ``OSError`` (a full disk, a read-only folder, a file-size limit) is
raised again naming the target, not the temporary file.
"""

from __future__ import annotations

import os
import tempfile
from collections.abc import Callable
from pathlib import Path


def atomic_write_text(path: str | os.PathLike[str], text: str) -> None:
    """Write text to ``path`` through a temporary file in the same folder and a rename."""
    atomic_write_bytes(path, text.encode("utf-8"))


def named_os_error(e: OSError, path: str | os.PathLike[str]) -> OSError:
    """``e`` (same class and errno) naming ``path``: the file the user asked for."""
    err = type(e)(e.errno, e.strerror or str(e), str(path))
    return err if e.errno is not None else OSError(f"{path}: {e}")


def atomic_write_bytes(path: str | os.PathLike[str], data: bytes) -> None:
    """Write bytes to ``path`` through a temporary file in the same folder and a rename."""
    p = Path(path)
    try:
        fd, tmp = tempfile.mkstemp(prefix=f".{p.name}.", suffix=".tmp", dir=p.parent)
    except OSError as e:
        raise named_os_error(e, p) from None
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(data)
            f.flush()
            os.fsync(f.fileno())  # a full disk shows here, not after the rename
        os.replace(tmp, p)
    except OSError as e:
        Path(tmp).unlink(missing_ok=True)
        raise named_os_error(e, p) from None
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def atomic_write_with(path: str | os.PathLike[str], writer: Callable[[str], None],
                      suffix: str = "") -> None:
    """Call ``writer(tmp_path)`` (a library that insists on writing a path itself), then
    rename the result to ``path``; ``suffix`` keeps an extension the library needs."""
    p = Path(path)
    try:
        fd, tmp = tempfile.mkstemp(prefix=f".{p.stem}.", suffix=f".tmp{suffix}", dir=p.parent)
    except OSError as e:
        raise named_os_error(e, p) from None
    os.close(fd)
    try:
        writer(tmp)
        os.replace(tmp, p)
    except OSError as e:
        Path(tmp).unlink(missing_ok=True)
        raise named_os_error(e, p) from None
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
