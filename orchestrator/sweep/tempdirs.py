"""A sweep worker's private work folder, and the removal of the folders of dead workers.

Each worker writes its copies of the artifacts (and extracts the FMU) into
``<parent>/hpcosim-sweep-<digest>/<pid>-<random>`` (``parent``: Dask's worker folder, or the
temporary folder).  The worker holds a shared ``flock`` on its folder while it lives (the
lock of :mod:`human_fmu.instance`'s FMU extraction folders, reused here); the folder goes
with :meth:`WorkFolder.close`, and a worker killed with SIGKILL leaves it to the next
worker of the same sweep digest, which removes, before making its own, every folder of the
base whose lock nobody holds and whose process is dead, or alive but started after the
folder was last written (its PID reused by another process).

Safe against another local user: the base folder must be this user's own real folder (not a
symlink; made mode 0700, a group- or world-open one of ours is closed), else a one-line
``ValueError``; entries are examined without following links and only this user's are
removed.
"""

from __future__ import annotations

import contextlib
import fcntl
import os
import re
import shutil
import stat
import tempfile
from pathlib import Path

from human_fmu.instance import folder_held, pid_alive

#: a worker's folder in the base: ``<pid>-<random>`` (:func:`tempfile.mkdtemp`)
_OWNED = re.compile(r"(\d+)-")
#: a process whose start is this many seconds after a folder's last change did not write it
START_SLACK_S = 1.0


def _start_time(pid: int) -> float | None:
    """When process ``pid`` started (s since the epoch; Linux ``/proc``), None if unknown."""
    try:
        fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
        btime = next(int(line.split()[1]) for line in Path("/proc/stat").read_text()
                     .splitlines() if line.startswith("btime "))
        return btime + int(fields[19]) / os.sysconf("SC_CLK_TCK")
    except (OSError, IndexError, ValueError, StopIteration):
        return None


def _owner_gone(pid: int, mtime: float) -> bool:
    """No living process of ``pid`` can own a folder last written at ``mtime`` (s)."""
    if not pid_alive(pid):
        return True
    start = _start_time(pid)
    return start is not None and start > mtime + START_SLACK_S


def reap_dead(base: Path) -> list[Path]:
    """Remove this user's ``<pid>-*`` folders in ``base`` whose lock nobody holds and whose
    owner is gone (module doc); the paths removed."""
    gone = []
    with contextlib.suppress(OSError):
        for e in os.scandir(base):
            m = _OWNED.match(e.name)
            if m is None or not e.is_dir(follow_symlinks=False):
                continue
            st = e.stat(follow_symlinks=False)
            if (st.st_uid != os.geteuid() or not _owner_gone(int(m.group(1)), st.st_mtime)
                    or folder_held(e.path)):
                continue
            shutil.rmtree(e.path, ignore_errors=True)
            gone.append(Path(e.path))
    return gone


def private_base(base: Path) -> Path:
    """``base``, made (mode 0700) if missing; a one-line ``ValueError`` unless it is this
    user's own folder (a symlink, another user's folder or a file is refused)."""
    with contextlib.suppress(FileExistsError):
        base.mkdir(mode=0o700, parents=True)
    try:
        fd = os.open(base, os.O_RDONLY | os.O_DIRECTORY | os.O_NOFOLLOW | os.O_CLOEXEC)
    except OSError as e:
        raise ValueError(f"sweep work folder {base}: not a folder of its own (a symlink or "
                         f"a file?): {e.strerror or e}") from None
    try:
        st = os.fstat(fd)
        if st.st_uid != os.geteuid():
            raise ValueError(f"sweep work folder {base}: belongs to user {st.st_uid}, not "
                             f"to this user ({os.geteuid()}); remove it or use another "
                             "temporary folder (TMPDIR)")
        if stat.S_IMODE(st.st_mode) & 0o077:
            os.fchmod(fd, 0o700)
    finally:
        os.close(fd)
    return base


class WorkFolder:
    """This worker's private folder (mode 0700) under ``<parent>/hpcosim-sweep-<tag>``
    (``parent``: default the temporary folder), made after removing dead workers' folders
    (:func:`reap_dead`); locked until :meth:`close`, which removes it."""

    def __init__(self, tag: str, parent: Path | None = None) -> None:
        self.base = private_base(Path(parent or tempfile.gettempdir()) / f"hpcosim-sweep-{tag}")
        reap_dead(self.base)
        self.path = Path(tempfile.mkdtemp(prefix=f"{os.getpid()}-", dir=self.base))
        try:
            self._fd: int | None = os.open(self.path, os.O_RDONLY | os.O_DIRECTORY
                                           | os.O_NOFOLLOW | os.O_CLOEXEC)
            fcntl.flock(self._fd, fcntl.LOCK_SH)
        except BaseException:
            shutil.rmtree(self.path, ignore_errors=True)
            raise

    def close(self) -> None:
        """Remove the folder, then drop its lock (again: nothing)."""
        shutil.rmtree(self.path, ignore_errors=True)
        if self._fd is not None:
            with contextlib.suppress(OSError):
                os.close(self._fd)
            self._fd = None
