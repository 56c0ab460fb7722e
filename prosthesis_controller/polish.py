"""Solution polishing of the CLF-QP (as OSQP polishes): given the active set the
interior-point solver reports, re-solve the QP exactly with those constraints as equalities
and accept the point only if it is primal feasible and its multipliers have the right signs
-- then it satisfies the KKT conditions and IS the optimum, exact to round-off.

Why: the torque-to-output map Am has condition numbers up to ~2e3 on the default device
(knee and ankle torques act on y1 and y2 almost collinearly), so the u-space Hessian
Am^T Am reaches ~5e6 and interior-point iterates approach a vertex only to ~1e-5 N m.

The u-space QP (``clf_qp`` outputs Pu, cu, Gu, hu), z = (u_k, u_a[, rho]):

    min 1/2 u^T P u + c^T u + c_r rho   s.t.  g^T u - k rho <= h,  box bounds on u and rho

Float arithmetic on 2 x 2 blocks.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

_TOL = 1e-9


class PolishQp(NamedTuple):
    """The QP as :func:`polish` takes it: ``P`` (3x3 or 2x2), ``c``, ``g`` (the normalised
    row incl. the rho coefficient -k when ``relaxed``), ``h``; ``lower``/``upper`` the
    bounds of z."""

    P: np.ndarray
    c: np.ndarray
    g: np.ndarray
    h: float
    lower: np.ndarray
    upper: np.ndarray
    relaxed: bool


class ActiveGuess(NamedTuple):
    """A guessed active set: ``row`` the CLF row; ``knee``, ``ankle``, ``rho`` -1 at the
    variable's lower bound, +1 at its upper bound, 0 free."""

    row: bool
    knee: int
    ankle: int
    rho: int


class _Point(NamedTuple):
    """A candidate: the torques, rho and the row's multiplier."""

    u0: float
    u1: float
    rho: float
    lam: float


def polish(qp: PolishQp, guess: ActiveGuess) -> tuple[float, float, float] | None:
    """The exact optimum (u_k, u_a, rho) for the guessed active set, or None if the guess
    is not optimal."""
    c, g, xl, xu = qp.c, qp.g, qp.lower, qp.upper
    if qp.relaxed:
        cr, k = c[2], -g[2]
        if k <= 0.0:
            return None
    else:
        cr = k = 0.0
    rho = 0.0
    rho_free = qp.relaxed and guess.rho == 0
    if qp.relaxed and guess.rho:
        rho = xl[2] if guess.rho < 0 else xu[2]
    if rho_free and not guess.row:
        return None  # rho only in a linear cost, unconstrained: not an optimum
    eq = guess.row and not rho_free
    lam = 0.0
    c0, c1 = c[0], c[1]
    if guess.row and rho_free:  # rho absorbs the row: rho = (g u - h) / k, multiplier c_r / k
        lam = cr / k
        c0 += lam * g[0]
        c1 += lam * g[1]
    u = _torques(qp, (c0, c1), qp.h + k * rho, eq, guess)
    if u is None:
        return None
    u0, u1, lam_row = u
    if eq:
        lam = lam_row
    if guess.row and rho_free:
        rho = (g[0] * u0 + g[1] * u1 - qp.h) / k
    p = _Point(u0, u1, rho, lam)
    if not (_primal_feasible(qp, p, k) and _dual_feasible(qp, p, k, guess)):
        return None
    if not (math.isfinite(u0) and math.isfinite(u1) and math.isfinite(rho)):
        return None
    return u0, u1, rho


def _torques(qp: PolishQp, c: tuple[float, float], hh: float, eq: bool, guess: ActiveGuess
             ) -> tuple[float, float, float] | None:
    """(u_k, u_a, the row's multiplier if ``eq``) stationary with the fixed torques at their
    bounds and, if ``eq``, the row g u = hh held; linear cost ``c``; None if singular."""
    xl, xu = qp.lower, qp.upper
    u0 = xl[0] if guess.knee < 0 else xu[0] if guess.knee > 0 else 0.0
    u1 = xl[1] if guess.ankle < 0 else xu[1] if guess.ankle > 0 else 0.0
    if guess.knee == 0 and guess.ankle == 0:
        return _both_free(qp, c, hh, eq)
    if guess.knee == 0 or guess.ankle == 0:
        return _one_free(qp, c, hh, eq, guess.knee == 0, (u0, u1))
    if eq:
        return None  # both torques fixed and an equality row: degenerate vertex, skip
    return u0, u1, 0.0


def _both_free(qp: PolishQp, c: tuple[float, float], hh: float, eq: bool
               ) -> tuple[float, float, float] | None:
    P, g = qp.P, qp.g
    p00, p01, p11 = P[0, 0], P[0, 1], P[1, 1]
    c0, c1 = c
    g0, g1 = g[0], g[1]
    det = p00 * p11 - p01 * p01
    if det <= 0.0:
        return None
    a0 = -(p11 * c0 - p01 * c1) / det  # unconstrained minimiser
    a1 = -(p00 * c1 - p01 * c0) / det
    if not eq:
        return a0, a1, 0.0
    q0 = (p11 * g0 - p01 * g1) / det  # P^-1 g
    q1 = (p00 * g1 - p01 * g0) / det
    den = g0 * q0 + g1 * q1
    if den <= 0.0:
        return None
    mu = (g0 * a0 + g1 * a1 - hh) / den
    return a0 - mu * q0, a1 - mu * q1, mu


def _one_free(qp: PolishQp, c: tuple[float, float], hh: float, eq: bool, knee_free: bool,
              u: tuple[float, float]) -> tuple[float, float, float] | None:
    P, g = qp.P, qp.g
    if knee_free:
        pii, pij, ci, gi, gj, uj = P[0, 0], P[0, 1], c[0], g[0], g[1], u[1]
    else:
        pii, pij, ci, gi, gj, uj = P[1, 1], P[0, 1], c[1], g[1], g[0], u[0]
    lam = 0.0
    if eq:
        if abs(gi) < 1e-300:
            return None
        ui = (hh - gj * uj) / gi
        lam = -(pii * ui + pij * uj + ci) / gi
    else:
        if pii <= 0.0:
            return None
        ui = -(pij * uj + ci) / pii
    return (ui, u[1], lam) if knee_free else (u[0], ui, lam)


def _primal_feasible(qp: PolishQp, p: _Point, k: float) -> bool:
    """The row's multiplier is not negative and the point meets the row and the bounds."""
    g, h, xl, xu = qp.g, qp.h, qp.lower, qp.upper
    if p.lam < -_TOL:
        return False
    if g[0] * p.u0 + g[1] * p.u1 - k * p.rho > h + _TOL * (1.0 + abs(h)):
        return False
    for v, lo, hi in ((p.u0, xl[0], xu[0]), (p.u1, xl[1], xu[1])):
        if not (lo - _TOL * (1.0 + abs(lo)) <= v <= hi + _TOL * (1.0 + abs(hi))):
            return False
    return not qp.relaxed or -_TOL <= p.rho <= xu[2] + _TOL * (1.0 + xu[2])


def _dual_feasible(qp: PolishQp, p: _Point, k: float, guess: ActiveGuess) -> bool:
    """The bound multipliers from stationarity (grad + lam g = mu_lower - mu_upper) have
    the signs of the guessed active bounds (a variable whose two bounds coincide is fixed
    either way: no sign condition)."""
    P, c, g, xl, xu = qp.P, qp.c, qp.g, qp.lower, qp.upper
    gk = P[0, 0] * p.u0 + P[0, 1] * p.u1 + c[0] + p.lam * g[0]
    ga = P[0, 1] * p.u0 + P[1, 1] * p.u1 + c[1] + p.lam * g[1]
    for i, fix, grad in ((0, guess.knee, gk), (1, guess.ankle, ga)):
        if xl[i] < xu[i] and ((fix < 0 and grad < -_TOL) or (fix > 0 and grad > _TOL)):
            return False
    if qp.relaxed and guess.rho and xl[2] < xu[2]:
        grad = c[2] - p.lam * k
        if (guess.rho < 0 and grad < -_TOL) or (guess.rho > 0 and grad > _TOL):
            return False
    return True
