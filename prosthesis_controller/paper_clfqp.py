"""The paper's literal robust CLF-QP (``clfqp-paper``, ``clfqp-paper-exact``) on the
prosthesis subsystem with the socket force an exogenous input in the tube: relaxed and
smoothed (paper eq. robust_CLF_QP_relax) or exact (eq. robust_CLF_QP), a documented
negative result in the human-prosthesis loop.  See the package README, "Robust CLF-QP
(paper Sec. V)".

The generated ``clf_qp`` call gives the u-space QP (Pu, cu, Gu, hu) over
z = (u_k, u_a[, rho]); piqp solves it with the torque box and 0 <= rho <= rho_max as
bounds, rho in units of rho_max, and the solution is polished on the active set piqp
reports (:mod:`prosthesis_controller.polish`).
"""

from __future__ import annotations

import math

import numpy as np
import piqp

from prosthesis_controller.base import StanceResult, State
from prosthesis_controller.context import ControllerContext
from prosthesis_controller.interface import Active, ControllerName, QpOutcome
from prosthesis_controller.polish import ActiveGuess, PolishQp, polish
from prosthesis_controller.qp import DUAL_TOL, QpController, bound_side, dense_solver

_SLACK_TOL = 1e-4  # second polishing guess: constraints this close (relative) are active


class ClfQpController(QpController):
    """The paper's robust CLF-QP, relaxed (``clfqp-paper``) or exact
    (``clfqp-paper-exact``); module docstring."""

    name = ControllerName.CLFQP_PAPER

    def __init__(self, ctx: ControllerContext, relaxed: bool = True) -> None:
        n = 3 if relaxed else 2
        super().__init__(ctx, relaxed, n)
        c = ctx.config.clf
        self.name = ControllerName.CLFQP_PAPER if relaxed else ControllerName.CLFQP_PAPER_EXACT
        rho_max = float(c.rho_max)
        # the solver sees rho / rho_scale in [0, 1]: rho's range (up to 1e4) against the
        # torques' (~1) made piqp's iterations 2-6x more numerous
        self._rho_scale = rho_max if rho_max > 0 else 1.0
        if relaxed:
            self._xl[2], self._xu[2] = 0.0, rho_max / self._rho_scale
        #: z's units over the generated QP's (rho scaled)
        self._z_unit = np.array((1.0, 1.0, self._rho_scale))
        # the QP in the solver's variables, refreshed every tick (Fortran-ordered matrices)
        self._P = np.zeros((n, n), order="F")
        self._c = np.zeros(n)
        self._G = np.zeros((1, n), order="F")
        self._h = np.zeros(1)
        xl0, xu0 = self._xl.copy(), self._xu.copy()
        xl0[:2], xu0[:2] = -1.0, 1.0
        self._use_solver(dense_solver(
            float(c.solver_eps), P=np.asfortranarray(np.eye(n)), c=np.zeros(n),
            G=np.asfortranarray(np.ones((1, n))), h_l=np.array([-math.inf]), h_u=np.ones(1),
            x_l=xl0, x_u=xu0))
        self.qp_solution: np.ndarray | None = None  # (u_k, u_a[, rho]) of the last solve
        self._polish = bool(c.polish)

    def qp_data(self) -> tuple[np.ndarray, ...]:
        """The QP of the last stance tick as the solver got it, z = (u_k, u_a[, rho /
        rho_scale]): (P, c, G, h, x_l, x_u) with min 1/2 z^T P z + c^T z, G z <= h,
        x_l <= z <= x_u (copies; for cross-checks and benchmarks).  ``qp_solution`` is in
        the same variables."""
        return (np.array(self._P, order="F"), self._c.copy(), np.array(self._G, order="F"),
                self._h.copy(), self._xl.copy(), self._xu.copy())

    @property
    def rho_scale(self) -> float:
        """rho = rho_scale z[2] (1 for the exact QP)."""
        return self._rho_scale if self.relaxed else 1.0

    def _solver_qp(self) -> PolishQp:
        """The generated QP (``clf_qp`` outputs) in the solver's variables, into ``_P``,
        ``_c``, ``_G``, ``_h``; and as :func:`polish` takes it: the relaxed row normalised,
        rho in units of rho_scale; the exact QP's data as generated (its rho column
        unused)."""
        o = self._clf_out
        P, c, G, h = o["Pu"], o["cu"], o["Gu"], o["hu"]
        if self.relaxed:
            row = G[0] * self._z_unit
            norm = math.sqrt(sum(v * v for v in row.tolist()))
            self._G[0] = row / norm
            self._h[0] = h[0] / norm
            self._c[:] = c * self._z_unit
            self._P[:] = P
            return PolishQp(P, self._c, self._G[0], float(self._h[0]), self._xl, self._xu,
                            True)
        self._P[:] = P[:2, :2]
        self._G[0] = G[0, :2]
        self._c[:] = c[:2]
        self._h[0] = h[0]
        return PolishQp(P, c, G[0], float(h[0]), self._xl, self._xu, False)

    def _stance(self, t: float, since: float, x: State) -> StanceResult:
        self.qp_solution = None
        tau, V = self._clf_terms(x)
        if not math.isfinite(self._clf_out["check"][0]):
            return self._fall_back(x, tau, V, QpOutcome.NONFINITE)
        self._torque_box()
        qp = self._solver_qp()
        if _row_minimum(qp.g, self._xl, self._xu) > qp.h + 1e-9:  # the row cannot hold
            return self._fall_back(x, tau, V, QpOutcome.INFEASIBLE)
        s = self._solver
        s.update(P=self._P, c=self._c, G=self._G, h_u=self._h, x_l=self._xl, x_u=self._xu)
        if s.solve() != piqp.PIQP_SOLVED:
            return self._fall_back(x, tau, V, QpOutcome.FAILED)
        z = self._z.tolist()  # (u_k, u_a, rho / rho_scale)
        if not self.relaxed:
            z.append(0.0)
        if not all(math.isfinite(v) for v in z):
            return self._fall_back(x, tau, V, QpOutcome.NONFINITE)
        guess = self._active_guess()
        if self._polish:
            z, guess = self._polished(qp, z, guess)
        active = Active.CLF if guess.row else Active.NONE
        if guess.knee:
            active |= Active.KNEE_LOWER if guess.knee < 0 else Active.KNEE_UPPER
        if guess.ankle:
            active |= Active.ANKLE_LOWER if guess.ankle < 0 else Active.ANKLE_UPPER
        if guess.rho > 0:
            active |= Active.RHO_MAX
        self.qp_solution = np.array(z[:self._n])
        rho = z[2] * self._rho_scale if self.relaxed else 0.0
        return StanceResult(z[0], z[1], tau, V, rho, QpOutcome.SOLVED, active)

    def _active_guess(self) -> ActiveGuess:
        """The active set at piqp's solution, from its multipliers."""
        zl, zu = self._lower_dual.tolist(), self._upper_dual.tolist()
        return ActiveGuess(bool(self._row_dual[0] > DUAL_TOL), bound_side(zl[0], zu[0]),
                           bound_side(zl[1], zu[1]),
                           bound_side(zl[2], zu[2]) if self.relaxed else 0)

    def _polished(self, qp: PolishQp, z: list[float], guess: ActiveGuess
                  ) -> tuple[list[float], ActiveGuess]:
        """z re-solved exactly on the active set ``guess`` (a second guess from the slacks
        when the multipliers do not give the optimum: weakly active constraints), and the
        active set used; z unchanged when neither guess is the optimum."""
        xl, xu, g, h = qp.lower, qp.upper, qp.g, qp.h
        zp = polish(qp, guess)
        if zp is None:
            slack = h - (g[0] * z[0] + g[1] * z[1] + (g[2] * z[2] if qp.relaxed else 0.0))
            guess = ActiveGuess(guess.row or slack < _SLACK_TOL * (1.0 + abs(h)),
                                _near(z[0], 0, xl, xu, guess.knee),
                                _near(z[1], 1, xl, xu, guess.ankle),
                                _near(z[2], 2, xl, xu, guess.rho) if qp.relaxed else 0)
            zp = polish(qp, guess)
        if zp is None:
            return z, guess
        return [zp[0], zp[1], zp[2] if qp.relaxed else z[2]], guess


def _row_minimum(g: np.ndarray, lower: np.ndarray, upper: np.ndarray) -> float:
    """min of g . z over the box lower <= z <= upper (exact: the vertex that minimises each
    term; a zero coefficient contributes nothing, also against an infinite bound)."""
    total = 0.0
    for gi, lo, hi in zip(g.tolist(), lower.tolist(), upper.tolist(), strict=False):
        if gi > 0.0:
            total += gi * lo
        elif gi < 0.0:
            total += gi * hi
    return total


def _near(v: float, i: int, xl: np.ndarray, xu: np.ndarray, fix: int) -> int:
    """-1 / +1 if v is within the slack tolerance of its lower / upper bound, else ``fix``."""
    lo, hi = xl[i], xu[i]
    if v - lo < _SLACK_TOL * (1.0 + abs(lo)):
        return -1
    if hi - v < _SLACK_TOL * (1.0 + abs(hi)):
        return 1
    return fix
