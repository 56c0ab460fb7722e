"""Solution polishing of the CLF-QP (as OSQP polishes): given the active set the
interior-point solver reports, re-solve the QP exactly with those constraints as equalities
and accept the point only if it is primal feasible and its multipliers have the right signs
-- then it satisfies the KKT conditions and IS the optimum, exact to round-off.

Why: the torque-to-output map Am has condition numbers up to ~2e3 on the default device
(knee and ankle torques act on y1 and y2 almost collinearly), so the u-space Hessian
Am^T Am reaches ~5e6 and interior-point iterates approach a vertex only to ~1e-5 N m.

The u-space QP (``clf_qp`` outputs Pu, cu, Gu, hu), z = (u_k, u_a[, rho]):

    min 1/2 u^T P u + c^T u + c_r rho   s.t.  g^T u - k rho <= h,  box bounds on u and rho

Pure float arithmetic on 2 x 2 blocks (no numpy in the tick).
"""

from __future__ import annotations

import math

_TOL = 1e-9


def polish(P, c, g_row, h: float, xl, xu, relaxed: bool,
           row: bool, fix_k: int, fix_a: int, fix_r: int) -> tuple[float, float, float] | None:
    """The exact optimum for the guessed active set, or None if the guess is not optimal.

    ``P`` (3x3 or 2x2 array), ``c``, ``g_row`` (the normalised row incl. the rho
    coefficient -k when ``relaxed``), ``h``; ``xl``/``xu`` the bounds of z; ``row``: the CLF
    row is active; ``fix_*``: -1 at the lower bound, +1 at the upper bound, 0 free."""
    p00, p01, p11 = P[0, 0], P[0, 1], P[1, 1]
    c0, c1 = c[0], c[1]
    g0, g1 = g_row[0], g_row[1]
    if relaxed:
        cr, k = c[2], -g_row[2]
        if k <= 0.0:
            return None
    else:
        cr = k = 0.0
    rho = 0.0
    rho_free = relaxed and fix_r == 0
    if relaxed and fix_r:
        rho = xl[2] if fix_r < 0 else xu[2]
    if rho_free and not row:
        return None  # rho only in a linear cost, unconstrained: not an optimum
    eq = row and not rho_free
    lam = 0.0
    if row and rho_free:  # rho absorbs the row: rho = (g u - h) / k, multiplier c_r / k
        lam = cr / k
        c0 += lam * g0
        c1 += lam * g1
    hh = h + k * rho
    u0 = xl[0] if fix_k < 0 else xu[0] if fix_k > 0 else 0.0
    u1 = xl[1] if fix_a < 0 else xu[1] if fix_a > 0 else 0.0
    if fix_k == 0 and fix_a == 0:
        det = p00 * p11 - p01 * p01
        if det <= 0.0:
            return None
        a0 = -(p11 * c0 - p01 * c1) / det  # unconstrained minimiser
        a1 = -(p00 * c1 - p01 * c0) / det
        if eq:
            q0 = (p11 * g0 - p01 * g1) / det  # P^-1 g
            q1 = (p00 * g1 - p01 * g0) / det
            den = g0 * q0 + g1 * q1
            if den <= 0.0:
                return None
            mu = (g0 * a0 + g1 * a1 - hh) / den
            u0, u1 = a0 - mu * q0, a1 - mu * q1
            lam = mu
        else:
            u0, u1 = a0, a1
    elif fix_k == 0 or fix_a == 0:  # one torque free
        if fix_k == 0:
            pii, pij, ci, gi, gj, uj = p00, p01, c0, g0, g1, u1
        else:
            pii, pij, ci, gi, gj, uj = p11, p01, c1, g1, g0, u0
        if eq:
            if abs(gi) < 1e-300:
                return None
            ui = (hh - gj * uj) / gi
            lam = -(pii * ui + pij * uj + ci) / gi
        else:
            if pii <= 0.0:
                return None
            ui = -(pij * uj + ci) / pii
        if fix_k == 0:
            u0 = ui
        else:
            u1 = ui
    elif eq:
        return None  # both torques fixed and an equality row: degenerate vertex, skip
    if row and rho_free:
        rho = (g0 * u0 + g1 * u1 - h) / k
    # primal feasibility
    if lam < -_TOL:
        return None
    if g0 * u0 + g1 * u1 - k * rho > h + _TOL * (1.0 + abs(h)):
        return None
    for v, lo, hi in ((u0, xl[0], xu[0]), (u1, xl[1], xu[1])):
        if not (lo - _TOL * (1.0 + abs(lo)) <= v <= hi + _TOL * (1.0 + abs(hi))):
            return None
    if relaxed and not (-_TOL <= rho <= xu[2] + _TOL * (1.0 + xu[2])):
        return None
    # bound multipliers from stationarity: grad + lam g = mu_lower - mu_upper
    gk = p00 * u0 + p01 * u1 + c[0] + lam * g0
    ga = p01 * u0 + p11 * u1 + c[1] + lam * g1
    # (a variable whose two bounds coincide is fixed either way: no sign condition)
    for i, fix, grad in ((0, fix_k, gk), (1, fix_a, ga)):
        if xl[i] < xu[i] and ((fix < 0 and grad < -_TOL) or (fix > 0 and grad > _TOL)):
            return None
    if relaxed and fix_r and xl[2] < xu[2]:
        grad = c[2] - lam * k
        if (fix_r < 0 and grad < -_TOL) or (fix_r > 0 and grad > _TOL):
            return None
    if not (math.isfinite(u0) and math.isfinite(u1) and math.isfinite(rho)):
        return None
    return u0, u1, rho

