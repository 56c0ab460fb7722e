"""Line plots as PNG with Pillow: the QA figures of ``hpcosim mocap process``.

The figures are many thin polylines in a grid of panels with a frame, ticks, tick labels and
a title.  Matplotlib draws them well but costs about 1.2 s per take (0.5 s to import, 0.7 s
to lay out 16 axes and their ticks), more than half of the stage's time budget
(benchmarks/bench_mocap.py); Pillow draws them in a few tens of milliseconds.
"""

from __future__ import annotations

import io
import math
from collections.abc import Sequence

import numpy as np
from PIL import Image, ImageDraw, ImageFont

from characterization.mocap.limb_angles import runs

Color = tuple[int, int, int]
BLUE: Color = (31, 119, 180)  # matplotlib's tab10 colours
GREEN: Color = (44, 160, 44)
PINK: Color = (227, 119, 194)
INK: Color = (40, 40, 40)
GRID: Color = (225, 225, 225)


def nice_ticks(lo: float, hi: float, n: int = 5) -> list[float]:
    """About ``n`` round values (1, 2, 2.5 or 5 times a power of ten) within [lo, hi]."""
    raw = (hi - lo) / max(n - 1, 1)
    mag = 10.0 ** math.floor(math.log10(raw))
    step = next(m * mag for m in (1, 2, 2.5, 5, 10) if m * mag >= raw * 0.999)
    first = math.ceil(lo / step - 1e-9)
    return [round(k * step, 10) for k in range(first, math.floor(hi / step + 1e-9) + 1)]


def _bounds(segments: Sequence[np.ndarray]) -> tuple[float, float, float, float]:
    pts = [s[np.all(np.isfinite(s), axis=1)] for s in segments]
    pts = [p for p in pts if len(p)]
    if not pts:
        return 0.0, 1.0, 0.0, 1.0
    allp = np.concatenate(pts)
    (x0, y0), (x1, y1) = allp.min(axis=0), allp.max(axis=0)
    out = []
    for a, b in ((x0, x1), (y0, y1)):
        pad = 0.04 * (b - a) if b > a else max(1.0, abs(a) * 0.1)
        out += [float(a - pad), float(b + pad)]
    return out[0], out[1], out[2], out[3]


class Figure:
    """A white canvas of ``rows`` x ``cols`` panels, each with margins for its labels."""

    def __init__(self, width: int, height: int, rows: int, cols: int, font_size: int = 11
                 ) -> None:
        self.image = Image.new("RGB", (width, height), "white")
        self.draw = ImageDraw.Draw(self.image)
        self.font = ImageFont.load_default(size=font_size)
        self.rows, self.cols = rows, cols
        self.cell = (width / cols, height / rows)

    def panel(self, r: int, c: int, segments: Sequence[np.ndarray],
              colors: Sequence[Color], title: str, xlabel: str = "",
              legend: Sequence[tuple[str, Color]] = ()) -> None:
        """Polylines ``segments`` ((m, 2) arrays of x, y; NaN points break a line) in panel
        (r, c), each in its colour, with ticks at round values and the title above."""
        cw, ch = self.cell
        left, top = c * cw + 46, r * ch + 18
        right, bottom = (c + 1) * cw - 8, (r + 1) * ch - (34 if xlabel else 22)
        x0, x1, y0, y1 = _bounds(segments)
        sx, sy = (right - left) / (x1 - x0), (bottom - top) / (y1 - y0)
        d, f = self.draw, self.font
        for v in nice_ticks(y0, y1, 5):
            py = bottom - (v - y0) * sy
            d.line((left, py, right, py), fill=GRID)
            d.text((left - 4, py), f"{v:g}", fill=INK, font=f, anchor="rm")
        for v in nice_ticks(x0, x1, 5):
            px = left + (v - x0) * sx
            d.line((px, top, px, bottom), fill=GRID)
            d.text((px, bottom + 3), f"{v:g}", fill=INK, font=f, anchor="ma")
        for seg, col in zip(segments, colors, strict=True):
            xs = left + (seg[:, 0] - x0) * sx
            ys = bottom - (seg[:, 1] - y0) * sy
            ok = np.isfinite(xs) & np.isfinite(ys)
            for a, b in runs(ok):
                if b - a > 1:
                    d.line(np.column_stack([xs[a:b], ys[a:b]]).ravel().tolist(), fill=col)
        d.rectangle((left, top, right, bottom), outline=INK)
        d.text(((left + right) / 2, top - 3), title, fill=INK, font=f, anchor="md")
        if xlabel:
            d.text(((left + right) / 2, bottom + 17), xlabel, fill=INK, font=f, anchor="ma")
        for k, (name, col) in enumerate(legend):
            y = top + 10 + 14 * k
            d.line((right - 46, y, right - 30, y), fill=col, width=2)
            d.text((right - 26, y), name, fill=INK, font=f, anchor="lm")

    def png(self) -> bytes:
        buf = io.BytesIO()
        self.image.save(buf, format="png", compress_level=6)
        return buf.getvalue()

