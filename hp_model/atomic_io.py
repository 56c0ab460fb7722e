"""Atomic file output: a new temporary file in the target folder, then ``os.replace``.

The temporary file has an unpredictable name and is created exclusively (``O_CREAT |
O_EXCL | O_NOFOLLOW``): never an existing file, never through a symbolic link, so a file
or link planted in a shared folder is neither written nor followed; the rename replaces
the target's directory entry (a link there is replaced, not followed).  The file is
created with mode 0o666 less the process's umask (what ``open(path, "w")`` gives; not
mkstemp's 0600), so outputs are as readable as the user's umask says.

A failed or interrupted write never leaves a partial file under the target name, nor the
temporary one; an ``OSError`` (a full disk, a read-only folder, a file-size limit) is
raised again naming the target, not the temporary file.
"""

from __future__ import annotations

import errno
import os
import secrets
from collections.abc import Callable
from pathlib import Path

#: flags of a new temporary output file (O_NOFOLLOW and O_CLOEXEC where the OS has them)
CREATE_FLAGS = (os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_NOFOLLOW", 0)
                | getattr(os, "O_CLOEXEC", 0))
#: the mode an output file is created with, before the umask (as ``open(path, "w")``)
FILE_MODE = 0o666


def current_umask() -> int:
    """The process's umask (Linux: read from /proc, no change; elsewhere set and restored)."""
    try:
        with open("/proc/self/status", encoding="ascii") as f:
            for line in f:
                if line.startswith("Umask:"):
                    return int(line.split()[1], 8)
    except (OSError, ValueError, IndexError):
        pass
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


def output_mode() -> int:
    """The mode a new output file gets: 0o666 less the umask."""
    return FILE_MODE & ~current_umask()


def create_temp(folder: Path, prefix: str, suffix: str = "") -> tuple[int, Path]:
    """A new empty file ``folder/<prefix><random><suffix>`` opened for writing (its fd and
    path): created exclusively, never through a symbolic link, mode 0o666 less the umask."""
    for _ in range(100):
        tmp = folder / f"{prefix}{secrets.token_hex(6)}{suffix}"
        try:
            return os.open(tmp, CREATE_FLAGS, FILE_MODE), tmp
        except FileExistsError:
            continue  # a name taken (or planted): draw another
    raise FileExistsError(errno.EEXIST, "no free temporary name", str(folder))


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
        fd, tmp = create_temp(p.parent, f".{p.name}.", ".tmp")
    except OSError as e:
        raise named_os_error(e, p) from None
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(data)
            f.flush()
            os.fsync(f.fileno())  # a full disk shows here, not after the rename
        os.replace(tmp, p)
    except OSError as e:
        tmp.unlink(missing_ok=True)
        raise named_os_error(e, p) from None
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


def atomic_write_with(path: str | os.PathLike[str], writer: Callable[[str], None],
                      suffix: str = "") -> None:
    """Call ``writer(tmp_path)`` (a library that insists on writing a path itself), then
    rename the result to ``path``; ``suffix`` keeps an extension the library needs.  The
    temporary file exists (created as :func:`create_temp` creates it) when ``writer`` opens
    it, so the library truncates that file rather than following anything planted."""
    p = Path(path)
    try:
        fd, tmp = create_temp(p.parent, f".{p.stem}.", f".tmp{suffix}")
    except OSError as e:
        raise named_os_error(e, p) from None
    os.close(fd)
    try:
        writer(str(tmp))
        os.replace(tmp, p)
    except OSError as e:
        tmp.unlink(missing_ok=True)
        raise named_os_error(e, p) from None
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
