"""Bezier polynomials on s in [0, 1] (paper Sec. IV-A).

    B(s) = sum_{i=0}^{m} alpha_i C(m, i) s^i (1 - s)^(m - i)

Coefficients are stored as an array of shape (n_outputs, m + 1).  Every function works on
numpy arrays and on CasADi symbols (SX/MX), so the regression, the optimizer, the simulator
and the controllers evaluate the same curves.
"""

from __future__ import annotations

from math import comb
from typing import TypeVar

import casadi as ca
import numpy as np

#: a CasADi symbol type (the basis of an SX scalar is an SX row, of an MX an MX row)
Sym = TypeVar("Sym", ca.SX, ca.MX)


def _basis_symbolic(m: int, s: Sym) -> Sym:
    """Row (1, m+1) of the Bernstein basis values at a CasADi scalar s."""
    return ca.horzcat(*[comb(m, i) * s**i * (1 - s) ** (m - i) for i in range(m + 1)])


def basis(m: int, s):
    """Row of the m+1 Bernstein basis values at s (numpy: shape (len(s), m+1) for arrays)."""
    if isinstance(s, ca.SX):
        return _basis_symbolic(m, s)
    if isinstance(s, ca.MX):
        return _basis_symbolic(m, s)
    s = np.asarray(s, dtype=float)
    i = np.arange(m + 1)
    c = np.array([comb(m, k) for k in i], dtype=float)
    return c * np.power.outer(s, i) * np.power.outer(1.0 - s, m - i)


def evaluate(alpha, s):
    """B(s) for every output: shape (n_outputs,) for scalar s, (len(s), n_outputs) for arrays
    (numpy); an (n_outputs, 1) column for a CasADi scalar s."""
    if isinstance(s, ca.SX | ca.MX) or isinstance(alpha, ca.SX | ca.MX):
        m = alpha.shape[1] - 1
        return alpha @ basis(m, s).T
    alpha = np.asarray(alpha, dtype=float)
    return basis(alpha.shape[1] - 1, s) @ alpha.T


def derivative(alpha):
    """Coefficients (degree m-1) of dB/ds; a degree-0 curve has derivative 0 (degree 0)."""
    m = alpha.shape[1] - 1
    if m == 0:
        return alpha * 0
    return m * (alpha[:, 1:] - alpha[:, :-1])


def evaluate_continued(alpha, s, order: int = 1):
    """(B, dB/ds, d2B/ds2) of the rows of ``alpha`` at a CasADi scalar ``s``, continued
    outside [0, 1] by the Taylor polynomial of ``order`` at the nearer end, s_c = clip(s, 0, 1):

    - ``order`` 1 (C^1): B(s_c) + B'(s_c)(s - s_c), so d2B/ds2 = 0 outside (a jump at the
      ends: not for anything that must be C^2 there);
    - ``order`` 2 (C^2): + B''(s_c)(s - s_c)^2 / 2, so d2B/ds2 = B''(s_c) outside: the
      accelerations a curve asks for, and the forces they take, stay continuous at the ends.

    A degree-m polynomial extrapolated beyond its interval bends away within a few percent
    of the phase (and ill-conditions anything that inverts it); the continuation keeps the
    last velocity (and curvature).  (n_outputs, 1) columns."""
    if order not in (1, 2):
        raise ValueError(f"order must be 1 or 2, got {order}")
    d1 = derivative(alpha)
    d2 = derivative(d1)
    sc = ca.fmin(ca.fmax(s, 0), 1)
    out = s - sc
    dB, ddB = evaluate(d1, sc), evaluate(d2, sc)
    if order == 1:
        inside = (s >= 0) * (s <= 1)
        return evaluate(alpha, sc) + dB * out, dB, ddB * inside
    return evaluate(alpha, sc) + dB * out + ddB * out**2 / 2, dB + ddB * out, ddB


def gram(m: int) -> np.ndarray:
    """G_ij = integral_0^1 B_i(s) B_j(s) ds, so integral (sum e_i B_i)^2 ds = e^T G e."""
    G = np.empty((m + 1, m + 1))
    for i in range(m + 1):
        for j in range(m + 1):
            G[i, j] = comb(m, i) * comb(m, j) / (comb(2 * m, i + j) * (2 * m + 1))
    return G


def integral_weights(m: int) -> np.ndarray:
    """w with integral_0^1 B(s) ds = w . alpha (every Bernstein polynomial integrates to
    1 / (m + 1))."""
    return np.full(m + 1, 1.0 / (m + 1))
