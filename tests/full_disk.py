"""A disk that fills up, for tests: run a child process whose files may not grow past
``limit`` bytes (``RLIMIT_FSIZE``, with SIGXFSZ ignored, so a write past it fails with
EFBIG exactly as one on a full disk fails with ENOSPC). Works as any user, root included."""

from __future__ import annotations

import resource
import signal
import subprocess
from collections.abc import Sequence
from typing import Any


def run_with_file_limit(argv: Sequence[str], limit: int, **kw: Any
                        ) -> subprocess.CompletedProcess[str]:
    """``subprocess.run(argv)`` with every file it (and its children) writes capped at
    ``limit`` bytes; output captured as text."""

    def cap() -> None:
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
        resource.setrlimit(resource.RLIMIT_FSIZE, (limit, limit))

    return subprocess.run(list(argv), preexec_fn=cap, capture_output=True, text=True,
                          check=False, **kw)
