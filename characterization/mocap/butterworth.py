"""Zero-phase Butterworth low-pass in numpy: scipy.signal's ``butter(..., output="sos")`` and
``sosfiltfilt`` (odd padding, steady-state initial conditions), without importing
scipy.signal, which costs about half a second at start-up of ``hpcosim mocap process``.

The coefficients follow scipy's steps (analog prototype, pre-warping at fs = 2, bilinear
transform, one second-order section per conjugate pole pair, the gain in the first section)
and the recursion is scipy's transposed direct form II, term for term, so the output
matches scipy's to rounding (``tests/test_mocap_filter.py``).
"""

from __future__ import annotations

import numpy as np


def butter_sos(order: int, wn: float) -> np.ndarray:
    """(n_sections, 6) second-order sections [b0, b1, b2, 1, a1, a2] of a digital
    Butterworth low-pass of ``order`` with cutoff ``wn`` (a fraction of Nyquist, 0 < wn < 1).
    """
    if order < 1 or not 0 < wn < 1:
        raise ValueError(f"Butterworth low-pass: order {order}, cutoff {wn} of Nyquist "
                         "(expected order >= 1 and 0 < cutoff < 1)")
    m = np.arange(-order + 1, order, 2)
    fs2 = 4.0  # 2 fs with fs = 2: frequencies as fractions of Nyquist
    warped = fs2 * np.tan(np.pi * wn / 2)
    p = warped * -np.exp(1j * np.pi * m / (2 * order))  # analog poles, left half plane
    pz = (fs2 + p) / (fs2 - p)  # bilinear transform; all zeros go to z = -1
    gain = float(np.real(warped ** order / np.prod(fs2 - p)))
    sections = []
    for c in pz[pz.imag >= 0]:  # one section per conjugate pair, one for a real pole
        if c.imag > 0:
            sections.append((abs(c), [1.0, 2.0, 1.0, 1.0, -2 * c.real,
                                      c.real * c.real + c.imag * c.imag]))
        else:
            sections.append((abs(c), [1.0, 1.0, 0.0, 1.0, -c.real, 0.0]))
    sections.sort(key=lambda s: s[0])  # the poles nearest the unit circle last
    sos = np.array([s for _, s in sections])
    sos[0, :3] *= gain
    return sos


def sos_zi(sos: np.ndarray) -> np.ndarray:
    """(n_sections, 2) state of each section in steady state under a unit step (scipy's
    ``sosfilt_zi``)."""
    zi = np.empty((len(sos), 2))
    scale = 1.0
    for s, (b0, b1, b2, _, a1, a2) in enumerate(sos.tolist()):
        z0 = ((b1 - a1 * b0) + (b2 - a2 * b0)) / ((1.0 + a1) + a2)
        zi[s] = scale * z0, scale * ((1.0 + a1) * z0 - (b1 - a1 * b0))
        scale *= (b0 + b1 + b2) / (1.0 + a1 + a2)
    return zi


def sosfilt(sos: np.ndarray, x: np.ndarray, zi: np.ndarray) -> np.ndarray:
    """Causal filtering of the 1-D ``x`` through the sections from state ``zi``."""
    y = np.asarray(x, float).tolist()
    for (b0, b1, b2, _, a1, a2), (z0, z1) in zip(sos.tolist(), zi.tolist(), strict=True):
        for n, xn in enumerate(y):
            yn = b0 * xn + z0
            z0 = b1 * xn - a1 * yn + z1
            z1 = b2 * xn - a2 * yn
            y[n] = yn
    return np.array(y)


def padlen(sos: np.ndarray) -> int:
    """Samples of odd extension at each end (scipy's default for ``sosfiltfilt``)."""
    ntaps = 2 * len(sos) + 1
    ntaps -= min(int(np.sum(sos[:, 2] == 0)), int(np.sum(sos[:, 5] == 0)))
    return 3 * ntaps


def sosfiltfilt(sos: np.ndarray, x: np.ndarray) -> np.ndarray:
    """Forward-backward (zero-phase) filtering of the 1-D ``x``, longer than ``padlen``."""
    x = np.asarray(x, float)
    edge = padlen(sos)
    if x.ndim != 1 or len(x) <= edge:
        raise ValueError(f"sosfiltfilt: need a 1-D signal longer than {edge} samples")
    ext = np.concatenate([2 * x[0] - x[edge:0:-1], x, 2 * x[-1] - x[-2:-edge - 2:-1]])
    zi = sos_zi(sos)
    y = sosfilt(sos, ext, zi * ext[0])
    y = sosfilt(sos, y[::-1], zi * y[-1])[::-1]
    return y[edge:-edge]
