"""Zero-phase Butterworth low-pass: ``scipy.signal.butter(..., output="sos")`` and
``scipy.signal.sosfiltfilt`` (its defaults: odd extension, steady-state initial
conditions), in numpy.

Why not scipy.signal itself: importing it imports its whole namespace and ``scipy.stats``
(0.4-0.9 s on the 2-core machines, against the 2 s a user waits for ``hpcosim mocap
process`` end to end), for two functions the mocap pipeline uses.  The steps are scipy's
(buttap, lp2lp_zpk and bilinear_zpk with fs = 2, one section per conjugate pole pair with
the poles nearest the unit circle last, the gain in the first; sosfilt_zi; odd_ext; direct
form II transposed).  For an odd order the zeros at -1 are spread over the sections
differently from scipy's ``zpk2sos``: the same transfer function.
``tests/test_mocap_filter.py`` checks the transfer function (1e-15) and the filtered
signals (1e-12 of their magnitude) against scipy.signal over orders 1-8, cutoffs 0.01-0.99 and
lengths, and for order 2 (the pipeline's) the sections, initial conditions and filtered
signals bit for bit (same operations in the same order: the gait fits downstream amplify a
last-bit difference).  A filter of order ``n`` runs ``ceil(n / 2)`` sections per sample in a Python
loop: about 6 ms per 10 000 samples for the pipeline's order 2.
"""

from __future__ import annotations

import math

import numpy as np


def butter_lowpass_sos(order: int, wn: float) -> np.ndarray:
    """Second-order sections (``(ceil(order / 2), 6)``: b0 b1 b2 1 a1 a2) of the digital
    Butterworth low-pass of ``order`` with cutoff ``wn`` as a fraction of the Nyquist
    frequency (0 < wn < 1): ``scipy.signal.butter(order, wn, output="sos")``."""
    if order < 1 or int(order) != order:
        raise ValueError(f"Butterworth order {order}: a positive integer is needed")
    if not 0.0 < wn < 1.0:
        raise ValueError(f"cutoff {wn} of the Nyquist frequency: 0 < cutoff < 1 is needed")
    n = int(order)
    warped = 4.0 * math.tan(math.pi * wn / 2.0)  # pre-warped, fs = 2
    m = np.arange(-n + 1, n, 2)
    p_analog = -np.exp(1j * np.pi * m / (2 * n)) * warped
    p = (4.0 + p_analog) / (4.0 - p_analog)  # bilinear transform; n zeros at z = -1
    k = float(np.real(warped ** n / np.prod(4.0 - p_analog)))
    # one section per conjugate pair (and the real pole, with a zero at the origin), the
    # poles farthest from the unit circle first; the gain in the first section
    upper = sorted((q for q in p if q.imag > 0), key=abs)
    sections = []
    if n % 2:
        real = float(np.real(p[np.argmin(np.abs(p.imag))]))
        sections.append((abs(real), [1.0, 1.0, 0.0, 1.0, -real, 0.0]))
    sections += [(abs(q), [1.0, 2.0, 1.0, 1.0, -2.0 * q.real, q.real * q.real + q.imag * q.imag])
                 for q in upper]
    sections.sort(key=lambda s: s[0])
    sos = np.array([s[1] for s in sections])
    sos[0, :3] *= k
    return sos


def sosfilt_zi(sos: np.ndarray) -> np.ndarray:
    """Initial conditions (``(n_sections, 2)``) of the step response's steady state, for a
    unit input: ``scipy.signal.sosfilt_zi``."""
    sos = np.asarray(sos, float)
    zi = np.empty((len(sos), 2))
    scale = 1.0
    for s, (b, a) in enumerate(zip(sos[:, :3], sos[:, 3:], strict=True)):
        # zi = A zi + B: (I - companion(a)^T) zi = b[1:] - a[1:] b0
        i_minus_a = np.array([[1.0 + a[1], -1.0], [a[2], 1.0]])
        zi[s] = scale * np.linalg.solve(i_minus_a, b[1:] - a[1:] * b[0])
        scale *= np.sum(b) / np.sum(a)
    return zi


def sosfilt(sos: np.ndarray, x: np.ndarray, zi: np.ndarray) -> np.ndarray:
    """``x`` (1-D) through the sections, direct form II transposed, from the states ``zi``."""
    out = np.asarray(x, float).tolist()
    for (b0, b1, b2, _, a1, a2), (z0, z1) in zip(np.asarray(sos, float).tolist(),
                                                  np.asarray(zi, float).tolist(), strict=True):
        for i, v in enumerate(out):
            y = b0 * v + z0
            z0 = b1 * v - a1 * y + z1
            z1 = b2 * v - a2 * y
            out[i] = y
    return np.array(out)


def pad_length(sos: np.ndarray) -> int:
    """Samples of odd extension on each side (scipy's default ``padlen``); a signal must be
    longer than this."""
    sos = np.asarray(sos)
    taps = 2 * len(sos) + 1 - min(int((sos[:, 2] == 0).sum()), int((sos[:, 5] == 0).sum()))
    return 3 * taps


def sosfiltfilt(sos: np.ndarray, x: np.ndarray) -> np.ndarray:
    """Forward-backward (zero-phase) filtering of ``x`` (1-D) with odd extension and
    steady-state initial conditions: ``scipy.signal.sosfiltfilt(sos, x)``."""
    x = np.asarray(x, float)
    edge = pad_length(sos)
    if x.ndim != 1 or x.size <= edge:
        raise ValueError(f"a 1-D signal longer than {edge} samples is needed (got shape "
                         f"{x.shape})")
    ext = np.concatenate((2 * x[0] - x[edge:0:-1], x, 2 * x[-1] - x[-2:-(edge + 2):-1]))
    zi = sosfilt_zi(sos)
    y = sosfilt(sos, ext, zi * ext[0])
    y = sosfilt(sos, y[::-1], zi * y[-1])[::-1]
    return y[edge:-edge]
