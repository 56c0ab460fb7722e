"""The not-a-knot cubic spline through samples, evaluated at other times:
``scipy.interpolate.CubicSpline(x, y)(xq)`` for 1-D ``y``, in numpy and Python floats.

Why not scipy.interpolate itself: importing it imports scipy.special and scipy.optimize
(0.4-1.0 s on the 2-core machines, against the 2 s a user waits for ``hpcosim mocap
process`` end to end), for the one spline the gap fill draws.  The steps are scipy's, in
scipy's order: the banded system of ``CubicSpline.__init__`` (not-a-knot at both ends),
LAPACK's ``dgtsv`` (Gaussian elimination with partial pivoting, one right-hand side), the
coefficients of ``CubicHermiteSpline`` and the power-basis evaluation of ``PPoly``
(``_ppoly.evaluate_poly1``: terms from the constant one up, powers by repeated products).
On x86-64, where neither scipy's LAPACK nor its evaluation fuses a multiply and an add,
the values are scipy's bit for bit (``tests/test_mocap_filter.py``; the gait fits
downstream amplify a last-bit difference); elsewhere they agree to rounding.  The solve is a
Python loop over the samples: about 2-3 ms per 5 000 samples.  Three samples (scipy draws a
parabola through them with a dense solve) go to scipy itself.
"""

from __future__ import annotations

import numpy as np


def not_a_knot_spline(x: np.ndarray, y: np.ndarray, xq: np.ndarray) -> np.ndarray:
    """Values at ``xq`` (within ``[x[0], x[-1]]``) of the not-a-knot cubic spline through
    ``(x, y)`` (``x`` strictly increasing, both finite, 1-D, at least two samples; two
    samples give the straight line)."""
    x = np.asarray(x, dtype=np.float64)
    y = np.asarray(y, dtype=np.float64)
    xq = np.asarray(xq, dtype=np.float64)
    n = len(x)
    if x.ndim != 1 or y.shape != x.shape or n < 2:
        raise ValueError(f"spline through {y.shape} values at {x.shape} times: two or more "
                         "samples of a 1-D signal are needed")
    if not (np.all(np.isfinite(x)) and np.all(np.isfinite(y))):
        raise ValueError("spline through non-finite samples")
    dx = np.diff(x)
    if np.any(dx <= 0):
        raise ValueError("spline through times that are not strictly increasing")
    if n == 3:
        from scipy.interpolate import CubicSpline  # a parabola: a dense solve in scipy
        return np.asarray(CubicSpline(x, y)(xq), dtype=np.float64)
    slope = np.diff(y) / dx
    if n == 2:  # both ends clamped to the one slope: the line through the two samples
        d, du, dl = [1.0, 1.0], [0.0], [0.0]
        b = [slope[0], slope[0]]
    else:
        A = np.zeros((3, n))  # scipy's banded layout: upper, diagonal, lower
        b_arr = np.empty(n)
        A[1, 1:-1] = 2 * (dx[:-1] + dx[1:])
        A[0, 2:] = dx[:-1]
        A[-1, :-2] = dx[1:]
        b_arr[1:-1] = 3 * (dx[1:] * slope[:-1] + dx[:-1] * slope[1:])
        A[1, 0] = dx[1]
        A[0, 1] = x[2] - x[0]
        d0 = x[2] - x[0]
        b_arr[0] = ((dx[0] + 2 * d0) * dx[1] * slope[0] + dx[0] ** 2 * slope[1]) / d0
        A[1, -1] = dx[-2]
        A[-1, -2] = x[-1] - x[-3]
        d1 = x[-1] - x[-3]
        b_arr[-1] = ((dx[-1] ** 2 * slope[-2] + (2 * d1 + dx[-1]) * dx[-2] * slope[-1])
                     / d1)
        du, d, dl = A[0, 1:].tolist(), A[1, :].tolist(), A[2, :-1].tolist()
        b = b_arr.tolist()
    s = np.array(_gtsv(dl, d, du, b))
    return _hermite_values(x, y, s, dx, slope, xq)


def _gtsv(dl: list[float], d: list[float], du: list[float], b: list[float]) -> list[float]:
    """The solution of the tridiagonal system (sub-, main and super-diagonal ``dl``, ``d``,
    ``du``; right-hand side ``b``), as LAPACK's ``dgtsv`` computes it for one right-hand
    side (the lists are overwritten).  dgtsv leaves the last sub-diagonal entry unused where
    this sets it to zero: the back substitution's ``- 0 * 0`` changes no value."""
    n = len(d)
    for i in range(n - 1):
        di, li = d[i], dl[i]
        if (di if di >= 0.0 else -di) >= (li if li >= 0.0 else -li):  # no row interchange
            if di == 0.0:
                raise ValueError(f"singular spline system at sample {i}")
            fact = li / di
            d[i + 1] -= fact * du[i]
            b[i + 1] -= fact * b[i]
            dl[i] = 0.0
        else:  # interchange rows i and i + 1
            fact = di / li
            d[i] = li
            temp = d[i + 1]
            d[i + 1] = du[i] - fact * temp
            if i < n - 2:
                dl[i] = du[i + 1]
                du[i + 1] = -fact * dl[i]
            else:
                dl[i] = 0.0
            du[i] = temp
            temp = b[i]
            b[i] = b[i + 1]
            b[i + 1] = temp - fact * b[i + 1]
    if d[n - 1] == 0.0:
        raise ValueError(f"singular spline system at sample {n - 1}")
    x1 = b[n - 1] = b[n - 1] / d[n - 1]
    x2 = 0.0
    for i in range(n - 2, -1, -1):
        x0 = b[i] = (b[i] - du[i] * x1 - dl[i] * x2) / d[i]
        x2, x1 = x1, x0
    return b


def _hermite_values(x: np.ndarray, y: np.ndarray, s: np.ndarray, dx: np.ndarray,
                    slope: np.ndarray, xq: np.ndarray) -> np.ndarray:
    """The cubic Hermite interpolant of values ``y`` and slopes ``s`` at ``x``, at ``xq``:
    ``CubicHermiteSpline``'s power-basis coefficients of each interval, evaluated as
    ``PPoly`` does."""
    i = np.clip(np.searchsorted(x, xq, side="right") - 1, 0, len(x) - 2)
    t = (s[:-1][i] + s[1:][i] - 2 * slope[i]) / dx[i]
    c0 = t / dx[i]
    c1 = (slope[i] - s[:-1][i]) / dx[i] - t
    c2, c3 = s[:-1][i], y[:-1][i]
    h = xq - x[i]
    z = h * h
    return (((0.0 + c3) + c2 * h) + c1 * z) + c0 * (z * h)
