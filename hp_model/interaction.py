"""The human-prosthesis loop restricted to the gait's nominal human: what the prosthesis's
torque does when a human hangs on the socket (prosthesis stance, ``ps``).

The paper's prosthesis subsystem treats the socket force F_s as an input independent of the
prosthesis torque.  In the loop it is not: the human hangs on the socket, and F_s answers the
torque.  Here the full 12-DOF model is evaluated with the human where the gait puts it, at the
phase the prosthesis measures:

- **walker state** (:func:`nominal_walker_state`) from x_p = (th_pk, th_pa, dth_pk, dth_pa)
  and the gait's ps parameters theta: the phase tau and its rate from the prosthesis alone
  (:meth:`hp_model.outputs.HipProgress.phase`); the human joints (th_lh, th_lk, th_la,
  th_rh) on their Bezier curves B(tau), their rates dB(tau) tau_dot; the socket joint
  q_f = 0; the walker placed on the prosthesis foot at x = 0 (:mod:`hp_model.placement`:
  the base velocity from J_foot qd = 0) (y2 = dy2 = 0 for the human's outputs);
- **the human's torques** from its feedback linearization given the prosthesis motor torque
  u_p (``hfl_ps`` of :class:`hp_model.outputs.VirtualConstraints`), then the constrained
  dynamics ``dyn_ps``: the prosthesis joint accelerations and the stance-foot wrench.

Both are exactly affine in u_p (the human's law is affine in u_p, the dynamics in u):

    x_p_dot   = f_r(x_p) + g_r(x_p) u_p        (4,), (4, 2)
    w_foot    = w_0(x_p) + W(x_p) u_p          (F_x, F_z, M_y) at the prosthesis sole, (3,), (3, 2)

so a controller's output dynamics are nu = Jo (f_r + g_r u_p) for any outputs of x_p.  On a
state of the nominal gait these equal the full loop's (``xdot_human_ps``) exactly; elsewhere
they are the loop's response with the human where it should be, the model error being what
the human does differently.

Functions (``InteractionModel.functions``; compiled by ``numeric()``):

    walker_ps(x_p, theta)                  -> q (12), qd (12), tau
    interaction_ps(x_p, theta, gains)      -> f (4), g (4, 2), w0 (3), W (3, 2), tau
    model_error_ps(x_p, theta, gains, qdd_p, u_p) -> d (2), nu (2), a (2), A (2, 2), tau

``model_error_ps``: with the paper's prosthesis outputs
(:func:`hp_model.outputs.stance_outputs`: y1 the hip velocity error, y2 the knee's deviation
from its Bezier curve) and Jo = d(y1, dy2)/dx_p, the output accelerations
nu = (dy1 [m/s^2], d2y2 [rad/s^2]) of a state x_p moving with the prosthesis joint
accelerations ``qdd_p`` (rad/s^2, e.g. the full loop's) are nu = Jo (dth_p, qdd_p); the
model's are a + A u_p (a = Jo f, A = Jo g); the model error is d = nu - (a + A u_p): what
the nominal-human model does not explain (zero wherever the human is on its nominal
outputs, e.g. along the gait).

``gains`` = (eps, kp, kd) of the human's tracking (the gait's); on the nominal human its
outputs are zero and the gains do not enter, but they are kept as inputs so that the same
function serves a human placed off its curves.
"""

from __future__ import annotations

import casadi as ca
import numpy as np

from hp_model.compiled import FunctionSet
from hp_model.domains import Domain
from hp_model.human_prosthesis import HumanProsthesisModel
from hp_model.outputs import VirtualConstraints, stance_outputs
from hp_model.placement import place

DOMAIN = Domain.PS


def nominal_walker_state(model: HumanProsthesisModel, vc: VirtualConstraints, x_p: ca.SX,
                         theta: ca.SX) -> tuple[ca.SX, ca.SX, ca.SX]:
    """(q, qd, tau) of the walker in ``vc.domain`` = ps with the prosthesis at x_p and the
    human on the gait's curves at the phase x_p gives (module docstring): the prosthesis
    joints of a zero state set to x_p, :meth:`VirtualConstraints.on_outputs` and
    :func:`hp_model.placement.place` at x = 0; symbolic."""
    if vc.domain != DOMAIN:
        raise ValueError("the restricted model is defined in prosthesis stance (ps)")
    nq = model.nq
    q0, qd0 = [ca.SX(0)] * nq, [ca.SX(0)] * nq
    for k, i in enumerate(model.roles[DOMAIN].prosthesis):
        q0[i], qd0[i] = x_p[k], x_p[2 + k]
    q, qd, tau = vc.on_outputs(ca.vertcat(*q0), ca.vertcat(*qd0), theta)
    q, qd = place(model, DOMAIN, q, qd)
    return q, qd, tau


class InteractionModel:
    """The restricted human-prosthesis dynamics of one model and Bezier degree (module
    docstring), symbolic in ``functions`` and compiled by :meth:`numeric`."""

    def __init__(self, model: HumanProsthesisModel, degree: int) -> None:
        self.model, self.degree = model, degree
        vc = VirtualConstraints(model, DOMAIN, degree)
        self.vc = vc
        x_p = ca.SX.sym("x_p", 4)
        theta = ca.SX.sym("theta", vc.n_params)
        gains = ca.SX.sym("gains", 3)
        u_p = ca.SX.sym("u_p", 2)
        q, qd, tau = nominal_walker_state(model, vc, x_p, theta)
        u = vc.functions[f"hfl_{DOMAIN}"](q, qd, theta, gains, u_p)
        qdd, lam = model.function(f"dyn_{DOMAIN}")(q, qd, u)
        r = model.roles[DOMAIN]
        xdot = ca.vertcat(x_p[2], x_p[3], qdd[r.knee], qdd[r.ankle])
        wrench = lam[0:3]
        zero = ca.DM.zeros(2)
        f = ca.substitute(xdot, u_p, zero)
        g = ca.jacobian(xdot, u_p)
        w0 = ca.substitute(wrench, u_p, zero)
        W = ca.jacobian(wrench, u_p)
        alpha, v_hip, p_min, p_max = vc.layout.unpack(theta)
        o = stance_outputs(vc.hip, x_p, alpha[r.prosthesis_rows[0], :], v_hip, p_min, p_max)
        Jo = ca.jacobian(ca.vertcat(o.y1, o.dy2), x_p)
        qdd_p = ca.SX.sym("qdd_p", 2)
        nu = Jo @ ca.vertcat(x_p[2], x_p[3], qdd_p)
        a_o, A_o = Jo @ f, Jo @ g
        d_o = nu - a_o - A_o @ u_p
        self.functions = {
            "walker_ps": ca.Function("walker_ps", [x_p, theta], [q, qd, tau],
                                     ["x_p", "theta"], ["q", "qd", "tau"]),
            "interaction_ps": ca.Function(
                "interaction_ps", [x_p, theta, gains], [f, g, w0, W, tau],
                ["x_p", "theta", "gains"], ["f", "g", "w0", "W", "tau"], {"cse": True}),
            "model_error_ps": ca.Function(
                "model_error_ps", [x_p, theta, gains, qdd_p, u_p], [d_o, nu, a_o, A_o, tau],
                ["x_p", "theta", "gains", "qdd_p", "u_p"], ["d", "nu", "a", "A", "tau"],
                {"cse": True}),
        }
        self._numeric: FunctionSet | None = None

    def numeric(self) -> FunctionSet:
        """The functions compiled to C (cached on disk by source hash), through buffers."""
        if self._numeric is None:
            self._numeric = FunctionSet(list(self.functions.values()),
                                        f"{self.model.name}_interaction_m{self.degree}")
        return self._numeric

    def walker_state(self, x_p: np.ndarray, theta: np.ndarray
                     ) -> tuple[np.ndarray, np.ndarray, float]:
        """Numeric (q, qd, tau) of :func:`nominal_walker_state` (copies)."""
        q, qd, tau = self.numeric()["walker_ps"](np.asarray(x_p, float), theta)
        return q.copy(), qd.copy(), float(tau[0])
