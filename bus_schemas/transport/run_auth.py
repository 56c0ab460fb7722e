"""Per-run credentials for the CAN-over-zenoh link: only the run's own plant and controller
can join it.

The orchestrator creates a random secret for each run (:class:`RunCredentials`); it never
appears on a command line or in an environment: the controller process reads it from a pipe
(its stdin).  Each side writes zenoh's user/password dictionary into a private folder
(mode 0700, file 0600, removed at the end of the run) and opens its session with zenoh's
``usrpwd`` transport authentication: a peer without the secret is refused at the transport
(its frames never reach the bus).  Both sides hold the dictionary, so the plant checks the
controller and the controller checks the plant.

Hardware-in-the-loop over a real CAN bus does not use this (AMPRO3's protocol has no key):
there, access to the physical bus is what protects the prosthesis.
"""

from __future__ import annotations

import os
import secrets
import shutil
import tempfile
from pathlib import Path
from typing import Any

ROLES = ("plant", "ctrl")
_KEY = "transport/auth/usrpwd"


class RunCredentials:
    """The secret of one run and the private dictionary file zenoh checks peers against.
    Use as a context manager (or call :meth:`close`) to remove the file."""

    def __init__(self, secret: str | None = None) -> None:
        self.secret = secret if secret is not None else secrets.token_urlsafe(32)
        if not self.secret or any(c in self.secret for c in ":\n\r "):
            raise ValueError("a run secret must be non-empty, without ':' or whitespace")
        self._dir = Path(tempfile.mkdtemp(prefix="hpcosim-auth-"))  # mode 0700
        self.dictionary = self._dir / "usrpwd.txt"
        fd = os.open(self.dictionary, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
        with os.fdopen(fd, "w") as f:
            f.write("".join(f"{r}:{self.secret}\n" for r in ROLES))

    def zenoh_options(self, role: str) -> dict[str, Any]:
        """zenoh config settings (``make_config(options=...)``) for ``role``."""
        if role not in ROLES:
            raise ValueError(f"role {role!r}: expected one of {ROLES}")
        return {f"{_KEY}/user": role, f"{_KEY}/password": self.secret,
                f"{_KEY}/dictionary_file": str(self.dictionary)}

    def close(self) -> None:
        shutil.rmtree(self._dir, ignore_errors=True)

    def __enter__(self) -> RunCredentials:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
