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

from hp_model.domains import Domain
from prosthesis_controller.base import StanceResult, State
from prosthesis_controller.context import ControllerContext
from prosthesis_controller.disturbance import DisturbanceEstimator
from prosthesis_controller.interface import Active, ControllerName, QpOutcome
from prosthesis_controller.qp import DUAL_TOL, QpController, dense_solver, set_tolerance
from prosthesis_controller.terms import LOOP_RHO_UNIT, LOOP_ROWS, LOOP_SIGMA_UNIT


class LoopClfQpController(QpController):
    """Interaction-aware robust CLF-QP, relaxed (``clfqp``) or exact (``clfqp-exact``)."""

    name = ControllerName.CLFQP

    def __init__(self, ctx: ControllerContext, relaxed: bool = True) -> None:
        c = ctx.config.clf
        un = ctx.config.uncertainty
        self.estimator = DisturbanceEstimator(un.filter_time, un.max_dt,
                                              un.monitor_tolerance)
        f = ctx.terms.numeric["clf_qp_loop"]
        layout = ctx.terms.clf_loop_layout
        # the online compensation's d_hat and the margin's gate: views into the generated
        # call's parameters
        self._d_hat = f.inputs[1][layout.offset("d_hat"):][:2]
        self._margin_gate = f.inputs[1][layout.offset("margin_gate"):][:1]
        super().__init__(ctx, relaxed, 4 if relaxed else 2)
        self.name = ControllerName.CLFQP if relaxed else ControllerName.CLFQP_EXACT
        if relaxed:
            self._xl[2:] = 0.0
            self._xu[2] = float(c.rho_max) / LOOP_RHO_UNIT
            self._xu[3] = float(ctx.config.contact.sigma_max) / LOOP_SIGMA_UNIT
        f.inputs[1][:] = ctx.clf_loop_params
        self._f = f
        #: the generated call's outputs by name (overwritten by every stance tick)
        self.terms_out = dict(zip(f.function.name_out(), f.outputs, strict=True))
        rows = len(LOOP_ROWS)
        self._P = np.zeros((2, 2), order="F")  # the exact QP's blocks
        self._G = np.zeros((rows, 2), order="F")
        self._c = np.zeros(2)
        self._eps = float(c.loop_solver_eps)
        n = self._n
        self._use_solver(dense_solver(
            self._eps, P=np.asfortranarray(np.eye(n)), c=np.zeros(n),
            G=np.asfortranarray(np.ones((rows, n))), h_l=np.full(rows, -math.inf),
            h_u=np.ones(rows), x_l=np.maximum(self._xl, -1.0), x_u=np.minimum(self._xu, 1.0)))
        self._qp_x: list[float] | None = None
        self.sigma = 0.0  # contact relaxation of the last solve (torque-equivalent units)
        me = ctx.tube.model_error
        self._exclude = float(me.exclude_after_touchdown) if me is not None else math.inf
        self._margin_on = bool(un.margin) and me is not None
        self._compensate = bool(un.compensate)
        self._comp_after = float(un.compensate_after)
        self._comp_tc = float(un.compensate_filter)
        self._comp_max_dt = float(un.max_dt)

    # -- the model-error estimate -----------------------------------------------------
    def _reset_estimator(self) -> None:
        self.estimator.reset()
        self._d_hat[:] = 0.0
        self._t_comp: float | None = None
        self._monitored = False  # the previous stance tick's state is where the bound is

    def _estimator_gap(self) -> None:
        self.estimator.restart()
        self._monitored = False

    def _estimate(self) -> tuple[tuple[float, float], bool, bool, int]:
        e = self.estimator
        if self._domain is not Domain.PS or not e.valid:
            return (0.0, 0.0), False, False, e.count
        return (e.d0, e.d1), True, e.flag, e.count

    def _compensation(self, t: float, since: float) -> None:
        """The online compensation's d_hat: the valid estimate low-passed again (T_c) from
        ``compensate_after`` after touchdown on; held otherwise."""
        est = self.estimator
        if since >= self._comp_after and est.valid:
            dt = t - self._t_comp if self._t_comp is not None else 0.0
            g = dt / (self._comp_tc + dt) if 0.0 < dt <= self._comp_max_dt else 0.0
            self._d_hat += g * (np.array((est.d0, est.d1)) - self._d_hat)
            self._t_comp = t
        else:
            self._t_comp = None

    # -- the QP -----------------------------------------------------------------------
    def _solve(self) -> bool:
        """piqp at the tolerance; once more at 100x it if that fails."""
        s = self._solver
        if s.solve() == piqp.PIQP_SOLVED:
            return True
        set_tolerance(s, 100.0 * self._eps)
        try:
            return s.solve() == piqp.PIQP_SOLVED
        finally:
            set_tolerance(s, self._eps)

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
        n, o = self._n, self.terms_out
        return (np.array(o["P"][:n, :n]), np.array(o["c"][:n]), np.array(o["G"][:, :n]),
                np.array(o["h"]), self._xl.copy(), self._xu.copy())

    def _update_solver(self) -> None:
        """The generated QP into piqp: as it is (relaxed) or its torque columns (exact)."""
        o = self.terms_out
        if self.relaxed:
            P, c, G = o["P"], o["c"], o["G"]
        else:
            P, c, G = self._P, self._c, self._G
            P[:] = o["P"][:2, :2]
            G[:] = o["G"][:, :2]
            c[:] = o["c"][:2]
        self._solver.update(P=P, c=c, G=G, h_u=o["h"], x_l=self._xl, x_u=self._xu)

    def _active_set(self) -> Active:
        """The constraints active at piqp's solution, from its multipliers."""
        rows = self._row_dual.tolist()
        lower, upper = self._lower_dual.tolist(), self._upper_dual.tolist()
        active = Active.CLF if rows[0] > DUAL_TOL else Active.NONE
        if any(v > DUAL_TOL for v in rows[1:]):  # a contact row
            active |= Active.CONTACT
        if lower[0] > DUAL_TOL:
            active |= Active.KNEE_LOWER
        elif upper[0] > DUAL_TOL:
            active |= Active.KNEE_UPPER
        if lower[1] > DUAL_TOL:
            active |= Active.ANKLE_LOWER
        elif upper[1] > DUAL_TOL:
            active |= Active.ANKLE_UPPER
        if self.relaxed and upper[2] > DUAL_TOL:
            active |= Active.RHO_MAX
        return active

    # -- the stance law ---------------------------------------------------------------
    def _stance(self, t: float, since: float, x: State) -> StanceResult:
        self._qp_x = None
        est = self.estimator
        est.update(t, x[2], x[3], self._u[0], self._u[1], self._monitored)
        # the bound is defined (and, if configured, in the CLF row) from the excluded time
        # after the switch to stance on, and over its phase range (in the generated call)
        self._monitored = since >= self._exclude
        if self._margin_on:
            self._margin_gate[0] = 1.0 if self._monitored else 0.0
        if self._compensate:
            self._compensation(t, since)
        f, o = self._f, self.terms_out
        f.inputs[0][:] = x
        f.call_inplace()
        tau, V = float(o["tau"][0]), float(o["V"][0])
        if not math.isfinite(o["check"][0]):
            est.restart()
            return self._fall_back(x, tau, V, QpOutcome.NONFINITE)
        est.store(t, x[2], x[3], o["estimator"].tolist())
        self._torque_box()
        self._update_solver()
        if not self._solve():
            return self._fall_back(x, tau, V, QpOutcome.FAILED)
        # piqp meets the bounds to its tolerance only: clamp
        z = [min(max(v, lo), hi) for v, lo, hi in
             zip(self._z.tolist(), self._xl.tolist(), self._xu.tolist(), strict=False)]
        if self.relaxed:  # max(0, v): 0 for a NaN
            rho = max(0.0, z[2]) * LOOP_RHO_UNIT
            self.sigma = max(0.0, z[3]) * LOOP_SIGMA_UNIT
        else:
            rho = self.sigma = 0.0
        if not (math.isfinite(z[0]) and math.isfinite(z[1]) and math.isfinite(rho)):
            return self._fall_back(x, tau, V, QpOutcome.NONFINITE)
        self._qp_x = z
        return StanceResult(z[0], z[1], tau, V, rho, QpOutcome.SOLVED, self._active_set())
