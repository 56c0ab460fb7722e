"""Symbolic rigid-body dynamics of a :class:`~hp_model.tree.PlanarTree` (CasADi SX).

Equations (paper eqs. robotDyn, holoConstr; REFERENCE.md Sec. 2):

    D(q) qdd + H(q, qd) = B u + J(q)^T lam,      J qdd + Jdot qd = 0.

D includes the drives' reflected rotor inertias on its diagonal (``Body.armature``); they
add nothing to H (a rotor spinning with its joint has no velocity-product term here).

H = C qd + G is built by Kane's projection, H = sum_i m_i Jv_i^T (Jdot_vi qd + g e_z)
(angular terms vanish in the plane since the angular Jacobian is constant), which is exact
and about 4x cheaper than differentiating D.  The constrained (KKT) system is solved with a
symbolic Cholesky factorisation of D and of the Schur complement J D^-1 J^T, both symmetric
positive definite, so the result is an explicit SX graph that generates plain C.
"""

from __future__ import annotations

import casadi as ca

from hp_model.tree import PlanarTree, body_poses, point_position


def mass_matrix_and_bias(tree: PlanarTree, q: ca.SX, qd: ca.SX) -> tuple[ca.SX, ca.SX]:
    """D(q) (nq x nq) and H(q, qd) = C qd + G (nq,) of the unconstrained tree."""
    poses = body_poses(tree, q)
    nq = tree.nq
    D = ca.SX.zeros(nq, nq)
    H = ca.SX.zeros(nq, 1)
    g = ca.DM([0.0, tree.gravity])
    for i, b in enumerate(tree.bodies):
        _, a = poses[i]
        if b.mass > 0:
            c = point_position(tree, q, b.name, b.com, poses)
            Jv = ca.jacobian(c, q)
            bias = ca.jtimes(Jv @ qd, q, qd)  # Jdot_v qd
            D += b.mass * (Jv.T @ Jv)
            H += b.mass * (Jv.T @ (bias + g))
        if b.inertia > 0:
            Jw = ca.jacobian(a, q)
            D += b.inertia * (Jw.T @ Jw)
    for coord, j in tree.armature.items():  # reflected rotor inertias: diag(armature)
        k = tree.coord_index(coord)
        D[k, k] += j
    return D, H


def energies(tree: PlanarTree, q: ca.SX, qd: ca.SX) -> tuple[ca.SX, ca.SX]:
    """Kinetic and potential energy (J) with the potential zero at z = 0."""
    D, _ = mass_matrix_and_bias(tree, q, qd)
    poses = body_poses(tree, q)
    V = ca.SX(0)
    for b in tree.bodies:
        if b.mass > 0:
            V += b.mass * tree.gravity * point_position(tree, q, b.name, b.com, poses)[1]
    return 0.5 * qd.T @ D @ qd, V


def constraint_terms(h: ca.SX, q: ca.SX, qd: ca.SX) -> tuple[ca.SX, ca.SX]:
    """J = dh/dq and Jdot qd for holonomic constraints h(q)."""
    J = ca.jacobian(h, q)
    return J, ca.jtimes(J @ qd, q, qd)


# -- symbolic linear algebra for SPD systems -------------------------------------------------
def cholesky(A: ca.SX) -> list[list[ca.SX]]:
    """Lower Cholesky factor of a symmetric positive definite SX matrix, as nested lists."""
    n = A.shape[0]
    L: list[list[ca.SX]] = [[ca.SX(0)] * n for _ in range(n)]
    for j in range(n):
        s = A[j, j]
        for k in range(j):
            s -= L[j][k] * L[j][k]
        L[j][j] = ca.sqrt(s)
        inv = 1 / L[j][j]
        for i in range(j + 1, n):
            s = A[i, j]
            for k in range(j):
                s -= L[i][k] * L[j][k]
            L[i][j] = s * inv
    return L


def cholesky_solve(L: list[list[ca.SX]], B: ca.SX) -> ca.SX:
    """Solve (L L^T) X = B by forward and back substitution."""
    n = len(L)
    cols = []
    for c in range(B.shape[1]):
        y: list[ca.SX] = [ca.SX(0)] * n
        for i in range(n):
            s = B[i, c]
            for k in range(i):
                s -= L[i][k] * y[k]
            y[i] = s / L[i][i]
        x: list[ca.SX] = [ca.SX(0)] * n
        for i in reversed(range(n)):
            s = y[i]
            for k in range(i + 1, n):
                s -= L[k][i] * x[k]
            x[i] = s / L[i][i]
        cols.append(ca.vertcat(*x))
    return ca.horzcat(*cols)


def kkt_solve(D: ca.SX, J: ca.SX, a: ca.SX, b: ca.SX) -> tuple[ca.SX, ca.SX]:
    """Solve [D  -J^T; J  0] [x; lam] = [a; b] for SPD D and full-row-rank J.

    x = D^-1 (a + J^T lam), lam = (J D^-1 J^T)^-1 (b - J D^-1 a).
    """
    LD = cholesky(D)
    X = cholesky_solve(LD, ca.horzcat(J.T, a))
    DinvJT, Dinva = X[:, : J.shape[0]], X[:, J.shape[0]]
    S = J @ DinvJT
    lam = cholesky_solve(cholesky(S), b - J @ Dinva)
    return Dinva + DinvJT @ lam, lam


def constrained_accel(D: ca.SX, H: ca.SX, Bu: ca.SX, J: ca.SX, Jdqd: ca.SX) -> tuple[ca.SX, ca.SX]:
    """qdd and constraint wrenches lam of D qdd + H = B u + J^T lam, J qdd + Jdot qd = 0."""
    return kkt_solve(D, J, Bu - H, -Jdqd)


def impact_map(D: ca.SX, E: ca.SX, qd_minus: ca.SX) -> tuple[ca.SX, ca.SX]:
    """Rigid impact: qd+ = (I - D^-1 E^T (E D^-1 E^T)^-1 E) qd-, and the impulse F_I.

    Solves [D  -E^T; E  0] [qd+; F_I] = [D qd-; 0] (Grizzle, Westervelt).
    """
    return kkt_solve(D, E, D @ qd_minus, ca.SX.zeros(E.shape[0], 1))
