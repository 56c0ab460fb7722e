"""Not-a-knot cubic spline interpolation in numpy: what ``scipy.interpolate.CubicSpline(x,
y)(xi)`` returns, without importing scipy.interpolate (with scipy.special, scipy.linalg and
scipy.optimize, about 0.6 s at start-up of ``hpcosim mocap process``).

The same equations as scipy's (knot slopes from a tridiagonal system with not-a-knot end
rows, then Hermite cubics per interval, Horner evaluation); the tridiagonal system is solved
by elimination without pivoting, which is stable here (the interior rows are diagonally
dominant), so values agree with scipy's to rounding (``tests/test_mocap_filter.py``).
"""

from __future__ import annotations

import numpy as np


def _solve_tridiagonal(lower: list[float], diag: list[float], upper: list[float],
                       rhs: list[float]) -> np.ndarray:
    """x with lower[i] x[i-1] + diag[i] x[i] + upper[i] x[i+1] = rhs[i] (Thomas)."""
    n = len(diag)
    c = [0.0] * n
    d = [0.0] * n
    c[0] = upper[0] / diag[0]
    d[0] = rhs[0] / diag[0]
    for i in range(1, n):
        m = diag[i] - lower[i] * c[i - 1]
        c[i] = upper[i] / m if i < n - 1 else 0.0
        d[i] = (rhs[i] - lower[i] * d[i - 1]) / m
    for i in range(n - 2, -1, -1):
        d[i] -= c[i] * d[i + 1]
    return np.array(d)


def cubic_spline(x: np.ndarray, y: np.ndarray, xi: np.ndarray) -> np.ndarray:
    """Values at ``xi`` of the not-a-knot cubic spline through (x, y); ``x`` strictly
    increasing, at least 4 points (scipy falls back to lower orders below that)."""
    x = np.asarray(x, float)
    y = np.asarray(y, float)
    n = len(x)
    if n < 4 or np.any(np.diff(x) <= 0):
        raise ValueError("cubic_spline: need at least 4 strictly increasing knots")
    dx = np.diff(x)
    slope = np.diff(y) / dx
    lower = np.zeros(n)
    diag = np.zeros(n)
    upper = np.zeros(n)
    b = np.zeros(n)
    diag[1:-1] = 2 * (dx[:-1] + dx[1:])
    upper[1:-1] = dx[:-1]
    lower[1:-1] = dx[1:]
    b[1:-1] = 3 * (dx[1:] * slope[:-1] + dx[:-1] * slope[1:])
    d = x[2] - x[0]
    diag[0], upper[0] = dx[1], d
    b[0] = ((dx[0] + 2 * d) * dx[1] * slope[0] + dx[0] ** 2 * slope[1]) / d
    d = x[-1] - x[-3]
    diag[-1], lower[-1] = dx[-2], d
    b[-1] = (dx[-1] ** 2 * slope[-2] + (2 * d + dx[-1]) * dx[-2] * slope[-1]) / d
    s = _solve_tridiagonal(lower.tolist(), diag.tolist(), upper.tolist(), b.tolist())
    t = (s[:-1] + s[1:] - 2 * slope) / dx
    c0 = t / dx
    c1 = (slope - s[:-1]) / dx - t
    xi = np.asarray(xi, float)
    k = np.clip(np.searchsorted(x, xi, side="right") - 1, 0, n - 2)
    h = xi - x[k]
    return ((c0[k] * h + c1[k]) * h + s[:-1][k]) * h + y[:-1][k]
