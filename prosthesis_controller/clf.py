"""The rapidly exponentially stabilizing CLF (RES-CLF) of the prosthesis outputs (paper Sec. V;
REFERENCE.md Sec. 2).

Output dynamics eta_dot = F eta + G mu with eta = (y1, y2, dy2),
F = [[0,0,0],[0,0,1],[0,0,0]], G = [[1,0],[0,0],[0,1]].  P solves the CARE
F^T P + P F - P G R^-1 G^T P + Q = 0, and

    V_eps(eta) = eta^T P_eps eta,   P_eps = I_eps P I_eps,   I_eps = diag(1, 1/eps, 1).

Only the relative-degree-2 position is scaled: with eta_eps = I_eps eta the output dynamics
are eta_eps_dot = (1/eps)(F eta_eps + G (eps mu)), so the LQR law eps mu = -R^-1 G^T P eta_eps
gives dV_eps/dt <= -(c3/eps) V_eps with c3 = lmin(Q)/lmax(P); any gamma <= c3 keeps the
condition dV_eps/dt <= -(gamma/eps) V_eps feasible without input bounds.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.linalg import solve_continuous_are

from prosthesis_controller.terms import F_OUT, G_OUT


@dataclass(frozen=True)
class ResClf:
    """P, P_eps and the constants c1 = lmin(P), c2 = lmax(P), c3 = lmin(Q)/lmax(P)."""

    P: np.ndarray
    P_eps: np.ndarray
    eps: float
    c1: float
    c2: float
    c3: float

    def value(self, eta: np.ndarray) -> float:
        return float(eta @ self.P_eps @ eta)


def res_clf(Q: np.ndarray, R: np.ndarray, eps: float) -> ResClf:
    """Solve the CARE once and scale P (module docstring)."""
    Q, R = np.asarray(Q, dtype=float), np.asarray(R, dtype=float)
    if not 0 < eps < 1:
        raise ValueError(f"eps must lie in (0, 1), got {eps}")
    P = solve_continuous_are(F_OUT, G_OUT, Q, R)
    P = 0.5 * (P + P.T)
    I_eps = np.diag([1.0, 1.0 / eps, 1.0])
    ev = np.linalg.eigvalsh(P)
    return ResClf(P=P, P_eps=I_eps @ P @ I_eps, eps=eps, c1=float(ev[0]), c2=float(ev[-1]),
                  c3=float(np.linalg.eigvalsh(Q)[0] / ev[-1]))
