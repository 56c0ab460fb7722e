"""The interaction-aware robust CLF-QP (``clfqp``, ``clfqp-exact``): the paper's CLF on the
paper's prosthesis outputs, with the model of what the torque does in the human-prosthesis
loop (:mod:`hp_model.interaction`) instead of the subsystem with an exogenous socket force.

Per stance tick one generated-C call (``terms.clf_qp_loop``) gives the QP in solver form over
z = (u_k, u_a, rho / rho_scale, sigma / sigma_scale): the robust CLF row (margin: the
characterised bound of the model error, when the tube carries one), five stance-foot contact
rows (friction cone, normal force, centre of pressure), the cost |nu|^2 + c_rho rho +
c_sigma sigma.  piqp (dense, set up once) solves it; the relaxed form bounds the torques by
the motor limits and the rate bound, rho in [0, rho_max], sigma in [0, sigma_max]; the exact
form (paper eq. robust_CLF_QP) has neither relaxation nor torque bounds (the output is
clamped), and falls back when infeasible.  See the package README.
"""

from __future__ import annotations

import itertools
import math

import numpy as np
import piqp

from prosthesis_controller.controllers import BaseController, ControllerContext
from prosthesis_controller.interface import (
    MODE_FALLBACK,
    MODE_STANCE,
    QP_FAILED,
    QP_NONFINITE,
    QP_SOLVED,
    Active,
)
from prosthesis_controller.polish import polish_active_set
from prosthesis_controller.terms import LOOP_ROWS

_INF = math.inf
_DUAL_TOL = 1e-7
_SLACK_TOL = 1e-6  # second guess of the active set: multiplier AND this close (relative)
_N_ROWS = len(LOOP_ROWS)
_ROW_SETS = tuple(itertools.chain.from_iterable(
    itertools.combinations(range(_N_ROWS), k) for k in (0, 1, 2)))


class LoopClfQpController(BaseController):
    """Interaction-aware robust CLF-QP, relaxed (``clfqp``) or exact (``clfqp-exact``)."""

    name = "clfqp"

    def __init__(self, ctx: ControllerContext, relaxed: bool = True) -> None:
        self.relaxed = relaxed
        c = ctx.config.clf
        n = 4 if relaxed else 2
        self._n = n
        lk, la = ctx.limits
        with_limits = c.limits_in_qp if relaxed else c.exact_limits_in_qp
        self._qlim = (lk, la) if with_limits else (_INF, _INF)
        self._du = float(c.delta_u) if relaxed else _INF
        self._rho_scale = float(c.rho_max) if c.rho_max > 0 else 1.0
        self._rho_on = 1.0 if c.rho_max > 0 else 0.0
        self._sigma_scale = float(ctx.config.contact.sigma_max)
        self._xl = np.full(n, -_INF)
        self._xu = np.full(n, _INF)
        if relaxed:
            self._xl[2:] = 0.0
            self._xu[2], self._xu[3] = self._rho_on, 1.0
        self._P = np.zeros((n, n), order="F")
        self._G = np.zeros((_N_ROWS, n), order="F")
        self._hl = np.full(_N_ROWS, -_INF)
        self._solver = piqp.DenseSolver()
        self._eps = float(c.loop_solver_eps)
        self._set_eps(self._eps)
        self._solver.settings.verbose = False
        xl0, xu0 = np.maximum(self._xl, -1.0), np.minimum(self._xu, 1.0)
        self._solver.setup(P=np.asfortranarray(np.eye(n)), c=np.zeros(n),
                           G=np.asfortranarray(np.ones((_N_ROWS, n))), h_l=self._hl,
                           h_u=np.ones(_N_ROWS), x_l=xl0, x_u=xu0)
        self.name = "clfqp" if relaxed else "clfqp-exact"
        self.qp_solution: np.ndarray | None = None
        self.sigma = 0.0  # contact relaxation of the last solve (torque-equivalent units)
        super().__init__(ctx)
        f = ctx.terms.numeric["clf_qp_loop"]
        f.inputs[1][:] = ctx.clf_loop_params
        self._f = f
        self._fx = f.inputs[0]
        o = dict(zip(f.function.name_out(), f.outputs, strict=True))
        self.terms_out = o
        self._oP, self._oc, self._oG, self._oh = o["P"], o["c"], o["G"], o["h"]
        self._ochk, self._otau, self._oV = o["check"], o["tau"], o["V"]

    def _set_eps(self, eps: float) -> None:
        st = self._solver.settings
        st.eps_abs = st.eps_rel = eps
        st.eps_duality_gap_abs = st.eps_duality_gap_rel = eps

    def _solve(self) -> bool:
        """piqp at the tolerance; once more at 100x it if that fails."""
        s = self._solver
        if s.solve() == piqp.PIQP_SOLVED:
            return True
        self._set_eps(100.0 * self._eps)
        try:
            return s.solve() == piqp.PIQP_SOLVED
        finally:
            self._set_eps(self._eps)

    def qp_data(self) -> tuple[np.ndarray, ...]:
        """The last stance tick's QP as the solver got it (copies): (P, c, G, h, x_l, x_u),
        min 1/2 z^T P z + c^T z, G z <= h, x_l <= z <= x_u."""
        n = self._n
        return (self._P.copy(), np.array(self._oc[:n]), self._G.copy(), np.array(self._oh),
                self._xl.copy(), self._xu.copy())

    def _bounds(self) -> None:
        du = self._du
        lk, la = self._qlim
        xl, xu = self._xl, self._xu
        a, b = self._u0 - du, self._u0 + du
        xl[0] = -lk if a < -lk else a
        xu[0] = lk if b > lk else b
        a, b = self._u1 - du, self._u1 + du
        xl[1] = -la if a < -la else a
        xu[1] = la if b > la else b

    def _stance(self, t, qk, qa, vk, va):
        self.qp_solution = None
        x = self._fx
        x[0], x[1], x[2], x[3] = qk, qa, vk, va
        self._f.call_inplace()
        tau, V = float(self._otau[0]), float(self._oV[0])
        if not math.isfinite(self._ochk[0]):
            uk, ua = self._fallback(t, qk, qa, vk, va)
            return uk, ua, tau, V, 0.0, QP_NONFINITE, 0, MODE_FALLBACK
        self._bounds()
        n = self._n
        P, G = self._P, self._G
        P[:, :] = self._oP[:n, :n]
        G[:, :] = self._oG[:, :n]
        s = self._solver
        s.update(P=P, c=self._oc[:n], G=G, h_u=self._oh, x_l=self._xl, x_u=self._xu)
        if not self._solve():
            uk, ua = self._fallback(t, qk, qa, vk, va)
            return uk, ua, tau, V, 0.0, QP_FAILED, 0, MODE_FALLBACK
        res = s.result
        z = res.x
        uk, ua = float(z[0]), float(z[1])
        rho = float(z[2]) * self._rho_scale if self.relaxed else 0.0
        self.sigma = float(z[3]) * self._sigma_scale if self.relaxed else 0.0
        if not (math.isfinite(uk) and math.isfinite(ua) and math.isfinite(rho)):
            uk, ua = self._fallback(t, qk, qa, vk, va)
            return uk, ua, tau, V, 0.0, QP_NONFINITE, 0, MODE_FALLBACK
        d = _DUAL_TOL
        zbl, zbu = res.z_bl, res.z_bu
        # polish (as OSQP): the exact optimum on piqp's active set, kept if it is the KKT
        # point (|nu|^2 is flat along A's weak direction: cond(A^T A) up to ~1e4, where the
        # interior point stops up to 1e-3 N m from the vertex)
        rows = [i for i in range(_N_ROWS) if res.z_u[i] > d]
        lower = [i for i in range(n) if zbl[i] > d]
        upper = [i for i in range(n) if zbu[i] > d and i not in lower]
        zp = polish_active_set(self._P, self._oc[:n], self._G, self._oh, self._xl,
                               self._xu, rows, lower, upper)
        if zp is None:  # a weak multiplier misread: keep only what is also tight
            xl, xu, G, hq = self._xl, self._xu, self._G, self._oh
            gz = G @ z
            rows = [i for i in rows if hq[i] - gz[i] < _SLACK_TOL * (1.0 + abs(hq[i]))]
            lower = [i for i in lower if z[i] - xl[i] < _SLACK_TOL * (1.0 + abs(xl[i]))]
            upper = [i for i in upper if xu[i] - z[i] < _SLACK_TOL * (1.0 + abs(xu[i]))]
            zp = polish_active_set(self._P, self._oc[:n], G, hq, xl, xu, rows, lower, upper)
            # last: any one or two rows with those bounds (a KKT point of this convex QP is
            # its optimum, so the first that passes is the answer)
            for cand in (_ROW_SETS if zp is None else ()):
                zp = polish_active_set(self._P, self._oc[:n], G, hq, xl, xu, cand, lower,
                                       upper)
                if zp is not None:
                    rows = list(cand)
                    break
        if zp is not None:
            z = zp
            uk, ua = float(z[0]), float(z[1])
            if self.relaxed:
                rho = float(z[2]) * self._rho_scale
                self.sigma = float(z[3]) * self._sigma_scale
        active = int(Active.CLF) if 0 in rows else 0
        if any(i in rows for i in range(1, _N_ROWS)):
            active |= int(Active.CONTACT)
        if zbl[0] > d:
            active |= int(Active.KNEE_LOWER)
        elif zbu[0] > d:
            active |= int(Active.KNEE_UPPER)
        if zbl[1] > d:
            active |= int(Active.ANKLE_LOWER)
        elif zbu[1] > d:
            active |= int(Active.ANKLE_UPPER)
        if self.relaxed and zbu[2] > d:
            active |= int(Active.RHO_MAX)
        self.qp_solution = np.array(z[:n])
        return uk, ua, tau, V, rho, QP_SOLVED, active, MODE_STANCE
