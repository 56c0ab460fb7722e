"""What the robust CLF-QP controllers (:mod:`~prosthesis_controller.paper_clfqp`,
:mod:`~prosthesis_controller.loop_clfqp`) share: the relaxed/exact switch, the torques' box
of every tick and the piqp solver, set up once and updated every tick.

Solver variables z = (u_k, u_a, ...): the motor torques (N m) first, then the controller's
scaled relaxations.  The box of the torques is the motor limits and the rate bound
|u - u_prev| <= delta_u (``ClfConfig``); the exact QP has no rate bound, and the motor
limits only with ``exact_limits_in_qp``.
"""

from __future__ import annotations

import math

import numpy as np
import piqp

from prosthesis_controller.base import BaseController
from prosthesis_controller.context import ControllerContext

#: a multiplier above this (normalised problem) marks an active constraint
DUAL_TOL = 1e-7


class QpController(BaseController):
    """A stance law that solves a QP over z with n variables every stance tick
    (:meth:`_use_solver` gives it its solver)."""

    def __init__(self, ctx: ControllerContext, relaxed: bool, n: int) -> None:
        self.relaxed = relaxed
        c = ctx.config.clf
        with_limits = c.limits_in_qp if relaxed else c.exact_limits_in_qp
        self._qlim = ctx.limits if with_limits else (math.inf, math.inf)
        self._du = float(c.delta_u) if relaxed else math.inf
        self._n = n
        #: the bounds of z for the current tick (the torques' box: :meth:`_torque_box`)
        self._xl = np.full(n, -math.inf)
        self._xu = np.full(n, math.inf)
        super().__init__(ctx)

    def _use_solver(self, solver: piqp.DenseSolver) -> None:
        """Solve with ``solver`` (set up: :func:`dense_solver`).  Its result is read through
        views made here once (piqp keeps the result vectors in place, only ``setup``
        resizes them; a view made per read costs ~0.3 us): ``_z`` the solution, ``_row_dual``,
        ``_lower_dual``, ``_upper_dual`` the multipliers of the rows and the bounds."""
        self._solver = solver
        res = solver.result
        self._z, self._row_dual = res.x, res.z_u
        self._lower_dual, self._upper_dual = res.z_bl, res.z_bu

    def _torque_box(self) -> None:
        """This tick's box of the torques into ``_xl[:2]``, ``_xu[:2]``:
        max(-u_max, u_prev - du) <= u <= min(u_max, u_prev + du)."""
        (u0, u1), du, (lk, la) = self._u, self._du, self._qlim
        xl, xu = self._xl, self._xu
        xl[0], xu[0] = max(u0 - du, -lk), min(u0 + du, lk)
        xl[1], xu[1] = max(u1 - du, -la), min(u1 + du, la)


def dense_solver(eps: float, **setup: np.ndarray) -> piqp.DenseSolver:
    """A piqp dense solver with tolerances ``eps`` (absolute, relative, duality gap), quiet,
    set up once with the placeholder problem ``setup`` (piqp's ``setup`` keywords) that
    fixes the sizes; every tick then updates the data."""
    s = piqp.DenseSolver()
    set_tolerance(s, eps)
    s.settings.verbose = False
    s.setup(**setup)
    return s


def set_tolerance(solver: piqp.DenseSolver, eps: float) -> None:
    """piqp's absolute, relative and duality-gap tolerances, all ``eps``."""
    st = solver.settings
    st.eps_abs = st.eps_rel = eps
    st.eps_duality_gap_abs = st.eps_duality_gap_rel = eps


def bound_side(lower_multiplier: float, upper_multiplier: float) -> int:
    """-1 if a variable's lower bound is active (its multiplier above :data:`DUAL_TOL`),
    else +1 if its upper bound is, else 0."""
    if lower_multiplier > DUAL_TOL:
        return -1
    return 1 if upper_multiplier > DUAL_TOL else 0
