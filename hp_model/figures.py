"""The one figure helper: a matplotlib figure as the bytes of an image file (PNG by default),
at the resolution of every figure hpcosim writes (the experiments', the sweep report's, the
gait's and the tube's).  matplotlib is the caller's import: this module imports none."""

from __future__ import annotations

import io
from typing import Any

#: dots per inch of every figure written
DPI = 110


def figure_bytes(fig: Any, fmt: str = "png") -> bytes:
    """The figure as a ``fmt`` file ("png", "pdf", "svg"), at :data:`DPI`; a figure pyplot
    manages (``plt.figure``, ``plt.subplots``) is closed after, freeing its memory."""
    buf = io.BytesIO()
    fig.savefig(buf, format=fmt, dpi=DPI)
    if fig.canvas.manager is not None:
        import matplotlib.pyplot as plt

        plt.close(fig)
    return buf.getvalue()
