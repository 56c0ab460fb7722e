"""Per-run credentials for the CAN-over-zenoh link: only the run's own plant and controller
can join it.

The orchestrator creates a random secret for each run (:class:`RunCredentials`); it never
appears on a command line or in an environment: the controller process reads it from a pipe
(its stdin).  Each side holds zenoh's user/password dictionary and opens its session with
zenoh's ``usrpwd`` transport authentication: a peer without the secret is refused at the
transport (its frames never reach the bus).  Both sides hold the dictionary, so the plant
checks the controller and the controller checks the plant.

The dictionary never touches a file system where it could outlive its process: on Linux it
is an anonymous in-memory file (``memfd_create``) that zenoh reads as
``/proc/self/fd/<n>``; it disappears with the process, even one killed by SIGKILL.
Elsewhere it is a private folder (mode 0700, file 0600) in the temporary folder whose name
carries the owning PID (``hpcosim-auth-<pid>-*``); it is removed at the end of the run, and
every new :class:`RunCredentials` first removes this user's folders whose process is dead
(and folders of the older unnamed form, ``hpcosim-auth-<random>``, older than an hour).

Hardware-in-the-loop over a real CAN bus does not use this (AMPRO3's protocol has no key):
there, access to the physical bus is what protects the prosthesis.
"""

from __future__ import annotations

import contextlib
import os
import re
import secrets
import shutil
import tempfile
import time
from pathlib import Path
from typing import Any

ROLES = ("plant", "ctrl")
_KEY = "transport/auth/usrpwd"
PREFIX = "hpcosim-auth-"
_OWNED = re.compile(rf"{PREFIX}(\d+)-")  # hpcosim-auth-<pid>-<random>
_LEGACY = re.compile(rf"{PREFIX}[a-z0-9_]{{8}}")  # mkdtemp's name before the PID was in it
LEGACY_AGE_S = 3600.0


def _pid_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # another user's process
        return True
    return True


def sweep_dead(folder: Path | None = None) -> list[Path]:
    """Remove this user's ``hpcosim-auth-*`` folders in ``folder`` (default: the temporary
    folder) whose process is dead, and legacy unnamed ones older than an hour; the paths
    removed."""
    base = Path(folder or tempfile.gettempdir())
    gone = []
    with contextlib.suppress(OSError):
        for e in os.scandir(base):
            if not e.name.startswith(PREFIX) or not e.is_dir(follow_symlinks=False):
                continue
            st = e.stat(follow_symlinks=False)
            m = _OWNED.match(e.name)
            dead = (not _pid_alive(int(m.group(1))) if m else
                    _LEGACY.fullmatch(e.name) is not None
                    and time.time() - st.st_mtime > LEGACY_AGE_S)
            if dead and st.st_uid == os.geteuid():
                shutil.rmtree(e.path, ignore_errors=True)
                gone.append(Path(e.path))
    return gone


class RunCredentials:
    """The secret of one run and the private dictionary zenoh checks peers against
    (:attr:`dictionary`: a path zenoh can read).  Use as a context manager (or call
    :meth:`close`) to release it; ``in_memory`` False (or no ``memfd_create``): the
    PID-named private folder instead of the in-memory file (module doc)."""

    def __init__(self, secret: str | None = None, *, in_memory: bool = True) -> None:
        self.secret = secret if secret is not None else secrets.token_urlsafe(32)
        if not self.secret or any(c in self.secret for c in ":\n\r "):
            raise ValueError("a run secret must be non-empty, without ':' or whitespace")
        text = "".join(f"{r}:{self.secret}\n" for r in ROLES).encode()
        sweep_dead()
        self._fd: int | None = None
        self._dir: Path | None = None
        if in_memory and hasattr(os, "memfd_create") and Path("/proc/self/fd").is_dir():
            self._fd = os.memfd_create("hpcosim-auth", os.MFD_CLOEXEC)
            os.write(self._fd, text)
            self.dictionary = Path(f"/proc/self/fd/{self._fd}")
        else:
            self._dir = Path(tempfile.mkdtemp(prefix=f"{PREFIX}{os.getpid()}-"))  # 0700
            self.dictionary = self._dir / "usrpwd.txt"
            fd = os.open(self.dictionary, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
            with os.fdopen(fd, "wb") as f:
                f.write(text)

    def zenoh_options(self, role: str) -> dict[str, Any]:
        """zenoh config settings (``make_config(options=...)``) for ``role``."""
        if role not in ROLES:
            raise ValueError(f"role {role!r}: expected one of {ROLES}")
        return {f"{_KEY}/user": role, f"{_KEY}/password": self.secret,
                f"{_KEY}/dictionary_file": str(self.dictionary)}

    def close(self) -> None:
        if self._fd is not None:
            with contextlib.suppress(OSError):
                os.close(self._fd)
            self._fd = None
        if self._dir is not None:
            shutil.rmtree(self._dir, ignore_errors=True)

    def __enter__(self) -> RunCredentials:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
