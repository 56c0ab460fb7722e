"""The interaction-aware robust CLF-QP (``clfqp``, ``clfqp-exact``): the paper's CLF on the
paper's prosthesis outputs, with the model of what the torque does in the human-prosthesis
loop (:mod:`hp_model.interaction`) instead of the subsystem with an exogenous socket force.

Per stance tick one generated-C call (``terms.clf_qp_loop``) gives the QP in solver form over
z = (u_k, u_a, rho / LOOP_RHO_UNIT, sigma / LOOP_SIGMA_UNIT): the robust CLF row (margin: the
characterised bound of the model error, when the tube carries one), five stance-foot contact
rows (friction cone, normal force, centre of pressure), the cost |nu|^2 + c_rho rho +
c_sigma sigma.  piqp (dense, set up once) solves it; the relaxed form bounds the torques by
the motor limits and the rate bound, rho in [0, rho_max], sigma in [0, sigma_max]; the exact
form (paper eq. robust_CLF_QP) has neither relaxation nor torque bounds (the output is
clamped), and falls back when infeasible.  See the package README.
"""

from __future__ import annotations

import math

import numpy as np
import piqp

from prosthesis_controller.controllers import BaseController, ControllerContext
from prosthesis_controller.disturbance import DisturbanceEstimator
from prosthesis_controller.interface import Active, ControllerMode, ControllerName, QpOutcome
from prosthesis_controller.terms import LOOP_RHO_UNIT, LOOP_ROWS, LOOP_SIGMA_UNIT

_INF = math.inf
_DUAL_TOL = 1e-7
_N_ROWS = len(LOOP_ROWS)
_CLF, _CONTACT = int(Active.CLF), int(Active.CONTACT)
_KNEE_LOWER, _KNEE_UPPER = int(Active.KNEE_LOWER), int(Active.KNEE_UPPER)
_ANKLE_LOWER, _ANKLE_UPPER = int(Active.ANKLE_LOWER), int(Active.ANKLE_UPPER)
_RHO_MAX = int(Active.RHO_MAX)
_SOLVED = piqp.PIQP_SOLVED
assert _N_ROWS == 6, "LoopClfQpController._stance reads the row multipliers one by one"


class LoopClfQpController(BaseController):
    """Interaction-aware robust CLF-QP, relaxed (``clfqp``) or exact (``clfqp-exact``)."""

    name = ControllerName.CLFQP

    def __init__(self, ctx: ControllerContext, relaxed: bool = True) -> None:
        self.relaxed = relaxed
        c = ctx.config.clf
        n = 4 if relaxed else 2
        self._n = n
        lk, la = ctx.limits
        with_limits = c.limits_in_qp if relaxed else c.exact_limits_in_qp
        self._qlim = (lk, la) if with_limits else (_INF, _INF)
        self._du = float(c.delta_u) if relaxed else _INF
        self._rho_scale, self._sigma_scale = LOOP_RHO_UNIT, LOOP_SIGMA_UNIT
        self._xl = np.full(n, -_INF)
        self._xu = np.full(n, _INF)
        if relaxed:
            self._xl[2:] = 0.0
            self._xu[2] = float(c.rho_max) / LOOP_RHO_UNIT
            self._xu[3] = float(ctx.config.contact.sigma_max) / LOOP_SIGMA_UNIT
        self._P = np.zeros((2, 2), order="F")  # the exact QP's blocks
        self._G = np.zeros((_N_ROWS, 2), order="F")
        self._c2 = np.zeros(2)
        self._hl = np.full(_N_ROWS, -_INF)
        self._solver = piqp.DenseSolver()
        self._eps = float(c.loop_solver_eps)
        self._set_eps(self._eps)
        self._solver.settings.verbose = False
        xl0, xu0 = np.maximum(self._xl, -1.0), np.minimum(self._xu, 1.0)
        self._solver.setup(P=np.asfortranarray(np.eye(n)), c=np.zeros(n),
                           G=np.asfortranarray(np.ones((_N_ROWS, n))), h_l=self._hl,
                           h_u=np.ones(_N_ROWS), x_l=xl0, x_u=xu0)
        # views of the solver's result vectors, made once: piqp keeps the result in place
        # (resized by setup only, which runs here once), and making a view costs ~0.3 us
        res = self._solver.result
        self._rx, self._rzu, self._rzbl, self._rzbu = res.x, res.z_u, res.z_bl, res.z_bu
        # memoryviews of the small numpy buffers written and read per tick: their items are
        # Python floats, set and got in ~half the time of numpy's scalar indexing
        self._xlm, self._xum = memoryview(self._xl), memoryview(self._xu)
        self._z2_max, self._z3_max = (float(self._xu[2]), float(self._xu[3])) if relaxed \
            else (0.0, 0.0)
        self.name = ControllerName.CLFQP if relaxed else ControllerName.CLFQP_EXACT
        self._qp_x: list[float] | None = None
        self.sigma = 0.0  # contact relaxation of the last solve (torque-equivalent units)
        un = ctx.config.uncertainty
        self.estimator = DisturbanceEstimator(un.filter_time, un.max_dt,
                                              un.monitor_tolerance)
        me = ctx.tube.model_error
        self._exclude = float(me.exclude_after_touchdown) if me is not None else _INF
        self._margin_on = bool(un.margin) and me is not None
        self._monitored = False  # the previous stance tick's state is where the bound is
        # the online compensation's d_hat: a view into the generated call's parameters
        self._compensate = bool(un.compensate)
        self._comp_after = float(un.compensate_after)
        self._comp_tc = float(un.compensate_filter)
        self._comp_max_dt = float(un.max_dt)
        self._t_comp: float | None = None
        self._pdhat = ctx.terms.numeric["clf_qp_loop"].inputs[1][
            ctx.terms.clf_loop_layout.offset("d_hat"):][:2]
        super().__init__(ctx)
        f = ctx.terms.numeric["clf_qp_loop"]
        f.inputs[1][:] = ctx.clf_loop_params
        self._f = f
        self._call = f.trigger  # f.call_inplace without the method call
        self._fx = memoryview(f.inputs[0])
        o = dict(zip(f.function.name_out(), f.outputs, strict=True))
        self.terms_out = o
        self._oP, self._oc, self._oG, self._oh = o["P"], o["c"], o["G"], o["h"]
        self._ochk, self._otau, self._oV = o["check"], o["tau"], o["V"]
        self._mchk, self._mtau, self._mV = (memoryview(o[k]) for k in ("check", "tau", "V"))
        self._oest = o["estimator"]
        self._pgate = f.inputs[1][ctx.terms.clf_loop_layout.offset("margin_gate"):][:1]

    def _reset_estimator(self) -> None:
        self.estimator.reset()
        self._pdhat[:] = 0.0
        self._t_comp = None
        self._monitored = False

    def _estimator_gap(self) -> None:
        self.estimator.restart()
        self._monitored = False

    def _estimate(self) -> tuple[tuple[float, float], bool, bool, int]:
        e = self.estimator
        if self._domain != "ps" or not e.valid:
            return (0.0, 0.0), False, False, e.count
        return (e.d0, e.d1), True, e.flag, e.count

    def _set_eps(self, eps: float) -> None:
        st = self._solver.settings
        st.eps_abs = st.eps_rel = eps
        st.eps_duality_gap_abs = st.eps_duality_gap_rel = eps

    def _solve(self) -> bool:
        """piqp at the tolerance; once more at 100x it if that fails."""
        return self._solver.solve() == _SOLVED or self._retry()

    def _retry(self) -> bool:
        """The failed solve once more at 100x the tolerance."""
        s = self._solver
        self._set_eps(100.0 * self._eps)
        try:
            return s.solve() == piqp.PIQP_SOLVED
        finally:
            self._set_eps(self._eps)

    @property
    def qp_solution(self) -> np.ndarray | None:
        """The last stance tick's QP solution z (clamped to its bounds), None when the tick
        solved no QP."""
        return None if self._qp_x is None else np.array(self._qp_x)

    @property
    def qp_duality_gap(self) -> float:
        """piqp's duality gap at the last solve: by weak duality the solution's cost exceeds
        the QP's optimum by at most this much."""
        return float(self._solver.result.info.duality_gap)

    def qp_data(self) -> tuple[np.ndarray, ...]:
        """The last stance tick's QP as the solver got it (copies): (P, c, G, h, x_l, x_u),
        min 1/2 z^T P z + c^T z, G z <= h, x_l <= z <= x_u."""
        n = self._n
        return (np.array(self._oP[:n, :n]), np.array(self._oc[:n]), np.array(self._oG[:, :n]),
                np.array(self._oh), self._xl.copy(), self._xu.copy())

    def _stance(self, t, qk, qa, vk, va):
        # Hot path (every stance tick, on the co-simulation's critical path): plain floats
        # wherever numpy would cost a scalar conversion (~0.1 us each); the solver's result
        # read through views made once (self._rx, ...); see the package README, "Tick".
        self._qp_x = None
        est = self.estimator
        est.update(t, vk, va, self._u0, self._u1, self._monitored)
        # the bound is defined (and, if configured, in the CLF row) from the excluded time
        # after the switch to stance on, and over its phase range (in the generated call)
        late = t - self._t_switch >= self._exclude  # type: ignore[operator]
        self._monitored = late
        if self._margin_on:
            self._pgate[0] = 1.0 if late else 0.0
        if self._compensate:  # the estimate, low-passed again (T_c), once settled
            if t - self._t_switch >= self._comp_after and est.valid:  # type: ignore[operator]
                dt = t - self._t_comp if self._t_comp is not None else 0.0
                g = dt / (self._comp_tc + dt) if 0.0 < dt <= self._comp_max_dt else 0.0
                self._pdhat[0] += g * (est.d0 - self._pdhat[0])
                self._pdhat[1] += g * (est.d1 - self._pdhat[1])
                self._t_comp = t
            else:
                self._t_comp = None
        x = self._fx
        x[0], x[1], x[2], x[3] = qk, qa, vk, va
        self._call()
        tau, V = self._mtau[0], self._mV[0]
        if not math.isfinite(self._mchk[0]):
            est.restart()
            uk, ua = self._fallback(t, qk, qa, vk, va)
            return uk, ua, tau, V, 0.0, QpOutcome.NONFINITE, 0, ControllerMode.FALLBACK
        est.store(t, vk, va, self._oest.tolist())
        # the torques' box (BaseController._bounds, in floats): max(-u_max, u_prev - du)
        # <= u <= min(u_max, u_prev + du)
        du = self._du
        lk, la = self._qlim
        a, b = self._u0 - du, self._u0 + du
        l0 = -lk if a < -lk else a
        h0 = lk if b > lk else b
        a, b = self._u1 - du, self._u1 + du
        l1 = -la if a < -la else a
        h1 = la if b > la else b
        xl, xu = self._xlm, self._xum
        xl[0], xu[0], xl[1], xu[1] = l0, h0, l1, h1
        xl, xu = self._xl, self._xu
        s = self._solver
        # positional: (P, c, A, b, G, h_l, h_u, x_l, x_u); keywords cost piqp's binding
        # ~0.8 us more
        if self.relaxed:  # the generated function's own (Fortran-ordered) buffers
            s.update(self._oP, self._oc, None, None, self._oG, None, self._oh, xl, xu)
        else:  # the (u, u) block and the torque columns
            P, G, c = self._P, self._G, self._c2
            P[:, :] = self._oP[:2, :2]
            G[:, :] = self._oG[:, :2]
            c[:] = self._oc[:2]
            s.update(P, c, None, None, G, None, self._oh, xl, xu)
        if s.solve() != _SOLVED and not self._retry():
            uk, ua = self._fallback(t, qk, qa, vk, va)
            return uk, ua, tau, V, 0.0, QpOutcome.FAILED, 0, ControllerMode.FALLBACK
        # piqp meets the bounds to its tolerance only: clamp.  Written out, min(max(v, lo),
        # hi) is `v = lo if lo > v else v; v = hi if hi < v else v` (the same for a NaN)
        z = self._rx.tolist()
        uk, ua = z[0], z[1]
        uk = l0 if l0 > uk else uk
        z[0] = uk = h0 if h0 < uk else uk
        ua = l1 if l1 > ua else ua
        z[1] = ua = h1 if h1 < ua else ua
        if self.relaxed:
            z2, z3, hi = z[2], z[3], self._z2_max
            z2 = 0.0 if z2 < 0.0 else z2
            z[2] = z2 = hi if hi < z2 else z2
            hi = self._z3_max
            z3 = 0.0 if z3 < 0.0 else z3
            z[3] = z3 = hi if hi < z3 else z3
            # max(0, v): 0 for a NaN
            rho = (z2 if z2 > 0.0 else 0.0) * self._rho_scale
            self.sigma = (z3 if z3 > 0.0 else 0.0) * self._sigma_scale
        else:
            rho = self.sigma = 0.0
        if not (math.isfinite(uk) and math.isfinite(ua) and math.isfinite(rho)):
            uk, ua = self._fallback(t, qk, qa, vk, va)
            return uk, ua, tau, V, 0.0, QpOutcome.NONFINITE, 0, ControllerMode.FALLBACK
        d = _DUAL_TOL
        zu = self._rzu.tolist()
        active = _CLF if zu[0] > d else 0
        if zu[1] > d or zu[2] > d or zu[3] > d or zu[4] > d or zu[5] > d:
            active |= _CONTACT
        zbl, zbu = self._rzbl.tolist(), self._rzbu.tolist()
        if zbl[0] > d:
            active |= _KNEE_LOWER
        elif zbu[0] > d:
            active |= _KNEE_UPPER
        if zbl[1] > d:
            active |= _ANKLE_LOWER
        elif zbu[1] > d:
            active |= _ANKLE_UPPER
        if self.relaxed and zbu[2] > d:
            active |= _RHO_MAX
        self._qp_x = z
        return uk, ua, tau, V, rho, QpOutcome.SOLVED, active, ControllerMode.STANCE
