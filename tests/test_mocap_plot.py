"""The QA figures' Pillow plotter (``characterization/mocap/plot.py``)."""

from __future__ import annotations

import io

import numpy as np
import pytest
from PIL import Image

from characterization.mocap import plot


@pytest.mark.parametrize(("lo", "hi", "expect"), [
    (0.0, 1.0, [0.0, 0.25, 0.5, 0.75, 1.0]),
    (-41.3, 12.2, [-40.0, -20.0, 0.0]),
    (2.4, 12.6, [5.0, 10.0]),
    (2.4, 11.0, [2.5, 5.0, 7.5, 10.0]),
    (-0.003, 0.0041, [-0.002, 0.0, 0.002, 0.004]),
])
def test_ticks_are_round_and_inside(lo: float, hi: float, expect: list[float]) -> None:
    assert plot.nice_ticks(lo, hi) == pytest.approx(expect)


def test_a_panel_draws_its_lines_inside_its_frame() -> None:
    fig = plot.Figure(300, 200, 1, 2)
    t = np.linspace(0.0, 1.0, 50)
    seg = np.column_stack([t, np.sin(6 * t)])
    seg[20:23, 1] = np.nan  # a break in the line
    fig.panel(0, 0, [seg], [plot.GREEN], "left", "tau", legend=(("ps", plot.GREEN),))
    fig.panel(0, 1, [], [], "empty")  # no data: a frame with unit axes
    img = Image.open(io.BytesIO(fig.png()))
    assert img.size == (300, 200) and img.format == "PNG"
    a = np.asarray(img.convert("RGB")).astype(int)
    green = np.all(a == plot.GREEN, axis=2)
    _, xs = np.nonzero(green)
    assert green.sum() > 100
    assert xs.min() >= 46 and xs.max() < 150 - 8  # in the left panel's frame
    assert not np.all(a[:, 150:] == 255)  # the right one has its frame
