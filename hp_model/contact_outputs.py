"""Virtual constraints of the multi-contact graph's domains (``DomainGraph.MULTICONTACT``).

The paper's outputs (:mod:`hp_model.outputs`: its formulas, its packed gait vector theta and
its curves) with the two changes a foot on its heel or toe needs:

- the phase's hip progress is exact: the hip's forward position over the domain's stance
  contact (its first contact: a flat sole, a heel or a toe), delta_p_hip(q) = x_hip(q) -
  x_c(q) (m), rates from its Jacobian J_p (the paper's linearisation about a flat foot under
  the ankle does not hold on a toe);
- the hip's rate follows a curve of the phase, y1 = d/dt delta_p_hip - V(tau) (m/s; V a
  Bezier polynomial, the last row of alpha; v_hip its mean), not a constant: a person's hip
  slows and speeds up within a stance, and holding it at a constant rate takes forces the
  ground cannot give;
- the outputs per domain (``Domain.y2_coords``, ``Domain.velocity_output``): on a flat foot
  the paper's (y1 and every joint but the stance ankle: 6 outputs, 6 degrees of freedom); on
  a toe the six joints (7 degrees of freedom and 6 torques: the walker pivots on its toe,
  the phase is the zero dynamics); in a double support (a closed chain with 5 degrees of
  freedom and 6 torques) y1, both hips, the leading leg's knee and its sole's world pitch
  (the foot rolling from the heel to flat lands when the pitch is zero, whatever the leg
  above it does: with the ankle's angle as the output instead, a prosthesis torque held
  over 1 ms let the shank's errors delay the landing until the trailing toe pulled on the
  ground): the trailing leg's knee and ankle close the chain (a bent
  leg; the leading leg is nearly straight, and closing the chain through it would turn a
  millimetre of hip into degrees of knee), and the legs' squeeze (the sixth torque
  direction, which moves nothing and presses the feet against each other along the ground):
  the leading contact's friction ratio follows a curve of the phase, F_x = R(tau) F_z (R the
  last row of alpha, from the fitted gait; a ratio, not a force, so that the contact stays in
  its friction cone while its normal force lags the fit's after the heel strike).  Without
  that row the torques of least norm picked a squeeze of their own: on openOFM's fit, at the
  fitted state itself, 90-140 N m more at each hip and the trailing toe's F_x 0.16 W from the
  fit's.  The human's torques control ``Domain.human_outputs`` (on a toe its four joints;
  leading a double support (``ds_h``) its hip, knee and sole and the squeeze, the
  prosthesis pushing off holding y1 and the other hip; trailing (``ds_p``) y1, the hips and
  the prosthesis sole's pitch, the prosthesis's knee and ankle holding its knee and the
  squeeze).  In ``ds_p`` the human cannot hold the squeeze: both legs are nearly straight as
  it starts (the trailing knee at 5 deg), and the human's four rows with the squeeze among
  them go singular there (condition number, rows scaled to 1, up to 3900 on the committed
  cycle, against at most 100 for the rows it holds now and 150 in ``ds_h``); given a
  prosthesis torque held over 1 ms, the human's torques then blew up and the heel left the
  ground with 0.48 kN of pull.  Every domain has as many rows as torques.

With qdd = a(q, qd) + b(q) u (the domain's constrained dynamics) and step = p_max - p_min:

    dy1  = J_p qdd + Jdot_p qd - dV/dtau tau_dot
    ddy2 = (S - dB/dtau J_p / step) qdd - d2B/dtau2 tau_dot^2 - dB/dtau Jdot_p qd / step

so A = [J_p b; M b], L_f = [J_p a + Jdot_p qd - dV/dtau tau_dot; M a - ...] (in a double
support also the squeeze's row: lam = lam_a(q, qd) + lam_b(q) u, the rows of the leading
contact's F_x - R(tau) F_z) and the feedback linearization is the paper's,
u = -A^-1 (L_f + v), v = (eps y1, kp y2 + kd dy2, 0), with one change: the simulated person
yields to its contacts.  Of the feedback's torques -A^-1 v it applies the largest share s in
[0, 1] for which the wrench the model predicts (lam, affine in u) keeps every contact on the
ground within a friction ratio of 0.7, the stance contact with 30 N of load and a double
support's trailing one unloading no further than to zero (:func:`feedback_share`;
:data:`PERSON_MU`, :data:`PERSON_MIN_LOAD`): u = -A^-1 (L_f + s v).  Where its curves ask
more of the ground than it can give (a posture that is not the gait's, a landing off its
time) a person gives up tracking before it slips, and the closed loop's outputs then obey
ddy2 = -s (kp y2 + kd dy2).  People walk well inside their friction cone (the friction
they use in level walking is 0.15-0.25 of the load; Redfern, Cham, Gielo-Perczak et al.,
Ergonomics 44(13), 2001); whole-body controllers of humanoids put the same contact bounds
on their torques (as constraints of a QP; here one line search, closed form, so that the
FMU's generated C holds it too).  Measured on the packaged person (held oracle, 20 draws,
10 steps): with its four joints' curves offset by U(-1, 1) deg it walks 20 (18 without),
by U(-3, 3) deg 8 (2), with Bezier perturbations U(0, 0.025) 9 (3); the nominal walk's
strides are the same to 0.3 ms.  ``feedback_<d>`` and ``hfeedback_<d>`` give the two parts
and the share.

Past tau = 1 (a touchdown later than designed) the curves of a single support come to rest
(:func:`hp_model.outputs.resting`: the swing leg holds its landing posture); a double
support's continue with their curvature (:func:`hp_model.outputs.continued_smoothly`, C^2:
the leading foot goes on rolling down onto its toe, and the accelerations the curves ask
for, so the contact forces, do not jump at tau = 1 or 0; continued linearly, a flat
landing 1-2 ms late made the trailing toe pull 0.42-0.44 kN on the ground at every step of
the committed cycle).  Below tau = 0 (a domain entered early) a single support's curves
continue linearly.

:class:`ContactConstraints` has the paper's function names and signatures
(:class:`hp_model.outputs.VirtualConstraints`: ``phase_<d>``, ``outputs_<d>`` (y1 = 0 where
there is no velocity output), ``fl_<d>``, ``hfl_<d>``), so :mod:`hp_model.closed_loop` and
the simulator run either; :func:`virtual_constraints` picks the one of a model's graph.
"""

from __future__ import annotations

from collections.abc import Callable

import casadi as ca
import numpy as np

from hp_model.compiled import FunctionSet
from hp_model.domains import Domain, DomainGraph
from hp_model.dynamics import constrained_accel, constraint_terms
from hp_model.human_prosthesis import HumanProsthesisModel
from hp_model.outputs import (
    Curve,
    GaitTerms,
    Num,
    ThetaLayout,
    VirtualConstraints,
    continued,
    continued_smoothly,
    outputs,
    resting,
)


def _entering_linearly(curve: Curve) -> Curve:
    """``curve`` on tau >= 0, continued linearly below (:func:`hp_model.outputs.continued`):
    a domain entered early (its phase still negative: a step shorter than the gait's) keeps
    the curves' first slope instead of the polynomials' extrapolation, which bends away
    within a few percent of the phase (on openOFM's gait the prosthesis ankle's swing curve
    gave 125 deg at tau = -0.16)."""

    def f(alpha: Num, tau: Num) -> tuple[Num, Num, Num]:
        early = tau < 0
        lin, cur = continued(alpha, tau), curve(alpha, tau)
        return tuple(ca.if_else(early, a, b) for a, b in zip(lin, cur, strict=True))

    return f


def theta_rows(d: Domain) -> int:
    """The rows of a multi-contact domain's curves (alpha) in its packed gait: its y2
    outputs', then the hip rate's where it has one, then a double support's squeeze."""
    return len(d.y2_coords) + int(d.velocity_output) + int(d.is_double_support)


#: an output named ``<frame>`` + this is the frame's world pitch (rad), not a coordinate
PITCH = "_pitch"


def selection(model: HumanProsthesisModel, names: tuple[str, ...]) -> np.ndarray:
    """(len(names), nq) rows S with the outputs' angles S q (rad): a coordinate's unit row,
    or for ``<frame>_pitch`` the frame's world pitch (exact: linear in q in a planar tree,
    :meth:`HumanProsthesisModel.pitch_row`)."""
    S = np.zeros((len(names), model.nq))
    for r, name in enumerate(names):
        if name.endswith(PITCH):
            S[r] = model.pitch_row(name[: -len(PITCH)])
        else:
            S[r, model.coord_names.index(name)] = 1.0
    return S


#: the simulated person's contact margin (:func:`feedback_share`): the friction ratio its
#: feedback keeps every contact within (the simulator calls a slip at 0.8) and the load it
#: leaves on its stance contact (N)
PERSON_MU = 0.7
PERSON_MIN_LOAD = 30.0


def feedback_share(wrench_ff: ca.SX, wrench_fb: ca.SX, domain: Domain) -> ca.SX:
    """The largest share s in [0, 1] of the feedback torques for which the predicted wrench
    wrench_ff + s wrench_fb (lam's rows, N) keeps every contact of ``domain`` on the ground
    within the friction ratio :data:`PERSON_MU`, the stance contact (the first) with at least
    :data:`PERSON_MIN_LOAD` of load, a double support's trailing contact with a load >= 0 (it
    unloads to its lift-off); 0 where the feedforward torques alone do not (the feedback
    cannot help there).  Each bound is affine in s: s <= -a / b where b > 0."""
    share, row = ca.SX(1), 0
    for k, contact in enumerate(domain.contacts):
        fx0, fz0 = wrench_ff[row], wrench_ff[row + 1]
        fx1, fz1 = wrench_fb[row], wrench_fb[row + 1]
        load = PERSON_MIN_LOAD if k == 0 else 0.0
        for a, b in ((fx0 - PERSON_MU * fz0, fx1 - PERSON_MU * fz1),
                     (-fx0 - PERSON_MU * fz0, -fx1 - PERSON_MU * fz1),
                     (load - fz0, -fz1)):
            share = ca.fmin(share, ca.if_else(b > 0, -a / ca.fmax(b, 1e-12), 1))
        row += contact.size
    return ca.fmax(share, 0)


def _yielding_laws(A: ca.SX, Lf: ca.SX, v: ca.SX, lam: ca.SX, u_sym: ca.SX, u_p: ca.SX,
                   domain: Domain) -> tuple[tuple[ca.SX, ca.SX, ca.SX], ...]:
    """The feedback linearization A u = -(L_f + s v) of all six torques, and of the human's
    four given the prosthesis motor torque u_p (``hfl``: its rows ``Domain.human_outputs``;
    in a double support they include the squeeze, so it holds the gait's friction ratio of
    the leading contact whatever u_p), each as its torques without feedback (v = 0), the
    feedback's torques and the share s of them applied (:func:`feedback_share`, from the
    wrench lam, affine in the torques u_sym).  One factorization per law for its two
    parts."""
    lam_u = ca.jacobian(lam, u_sym)
    lam_0 = ca.substitute(lam, u_sym, ca.DM.zeros(u_sym.numel()))
    parts = -ca.solve(A, ca.horzcat(Lf, v))
    u_ff, u_fb = parts[:, 0], parts[:, 1]
    share = feedback_share(lam_0 + lam_u @ u_ff, lam_u @ u_fb, domain)
    rows = list(domain.human_outputs)
    h_parts = ca.solve(A[rows, 0:4], -ca.horzcat(Lf[rows] + A[rows, 4:6] @ u_p, v[rows]))
    h_ff = ca.vertcat(h_parts[:, 0], u_p)
    h_fb = ca.vertcat(h_parts[:, 1], ca.DM.zeros(2))
    h_share = feedback_share(lam_0 + lam_u @ h_ff, lam_u @ h_fb, domain)
    return (u_ff, u_fb, share), (h_ff, h_fb, h_share)


def hip_progress(model: HumanProsthesisModel, domain: Domain) -> ca.SX:
    """delta_p_hip(q): the hip's forward position over ``domain``'s stance contact (its first
    contact: a flat sole, a heel or a toe), m; the numerator of the domain's phase."""
    frame = Domain(domain).contacts[0].frame
    return model.frame_expr("hip")[0] - model.frame_expr(frame)[0]


class ContactConstraints:
    """Phase, outputs and feedback linearization of one domain of the multi-contact graph
    (module docstring); ``degree`` the Bezier degree of its curves."""

    def __init__(self, model: HumanProsthesisModel, domain: str, degree: int = 5) -> None:
        d = Domain(domain)
        if d not in model.domains:
            raise ValueError(f"domain {d} is not in the {model.graph} graph")
        if degree < 1:
            raise ValueError("y2 needs a Bezier degree >= 1")
        self.model, self.domain, self.degree = model, d, degree
        n_y2 = len(d.y2_coords)
        self.layout = ThetaLayout(degree, theta_rows(d))
        self.n_params = self.layout.size
        q, qd, nq = model.q, model.qd, model.nq
        #: the frame the phase is measured from: the domain's first contact
        self.reference_frame = d.contacts[0].frame
        progress = hip_progress(model, d)
        Jp = ca.jacobian(progress, q)
        progress_dot = Jp @ qd
        Jpdot_qd = ca.jtimes(progress_dot, q, qd)
        SD = ca.DM(selection(model, d.y2_coords))

        theta = ca.SX.sym("theta", self.n_params)
        gains = ca.SX.sym("gains", 3)
        alpha, v_hip, p_min, p_max = self.layout.unpack(theta)
        curve = continued_smoothly if d.is_double_support else _entering_linearly(resting)
        o = outputs(SD @ q, SD @ qd, progress, progress_dot,
                    GaitTerms(alpha[:n_y2, :], v_hip, p_min, p_max), curve)
        step = p_max - p_min

        J, Jdqd = constraint_terms(model.h[d], q, qd)
        qdd, lam = constrained_accel(model.D, model.H, ca.DM(model.B) @ model.u, J, Jdqd)
        b = ca.jacobian(qdd, model.u)
        a = ca.substitute(qdd, model.u, ca.DM.zeros(model.nu))
        M = SD - o.db @ Jp / step
        A = M @ b
        Lf = M @ a - o.ddb * o.tau_dot**2 - o.db * Jpdot_qd / step
        v = gains[1] * o.y2 + gains[2] * o.dy2
        y1 = ca.SX(0)
        if d.velocity_output:  # the hip's rate on its own curve V(tau): alpha's next row
            V, dV, _ = curve(alpha[n_y2:n_y2 + 1, :], o.tau)
            y1 = progress_dot - V
            A = ca.vertcat(Jp @ b, A)
            Lf = ca.vertcat(Jp @ a + Jpdot_qd - dV * o.tau_dot, Lf)
            v = ca.vertcat(gains[0] * y1, v)
        #: in a double support (else None): (q, qd, theta, u) -> the squeeze row's error
        #: F_x - R(tau) F_z of the leading contact (N) and R(tau)
        self.squeeze: ca.Function | None = None
        if d.is_double_support:  # the squeeze: the leading contact's F_x / F_z on its curve
            ratio, _, _ = curve(alpha[-1:, :], o.tau)
            err = lam[0] - ratio * lam[1]  # the leading contact's (F_x, F_z[, M_y]), N
            A = ca.vertcat(A, ca.jacobian(err, model.u))
            Lf = ca.vertcat(Lf, ca.substitute(err, model.u, ca.DM.zeros(model.nu)))
            v = ca.vertcat(v, 0)
            self.squeeze = ca.Function(f"squeeze_{d}", [q, qd, theta, model.u], [err, ratio],
                                       ["q", "qd", "theta", "u"], ["error", "ratio"])
        #: (q, qd, theta) -> A: the stacked outputs' second derivatives (y1's first) per
        #: torque (rows in ``human_outputs`` order of the stack, columns the six torques,
        #: the prosthesis's motor torques last)
        self.decoupling = ca.Function(f"decoupling_{d}", [q, qd, theta], [A],
                                      ["q", "qd", "theta"], ["A"])
        u_p = ca.SX.sym("u_p", 2)
        full, human = _yielding_laws(A, Lf, v, lam, model.u, u_p, d)
        u = full[0] + full[2] * full[1]
        u_hfl = human[0] + human[2] * human[1]

        tau = o.tau
        self.functions = {
            f"phase_{d}": ca.Function(f"phase_{d}", [q, theta], [tau], ["q", "theta"], ["tau"]),
            f"outputs_{d}": ca.Function(f"outputs_{d}", [q, qd, theta], [y1, o.y2, o.dy2, tau],
                                        ["q", "qd", "theta"], ["y1", "y2", "dy2", "tau"]),
            f"fl_{d}": ca.Function(f"fl_{d}", [q, qd, theta, gains], [u, y1, o.y2, o.dy2, tau],
                                   ["q", "qd", "theta", "gains"],
                                   ["u", "y1", "y2", "dy2", "tau"]),
            f"hfl_{d}": ca.Function(f"hfl_{d}", [q, qd, theta, gains, u_p], [u_hfl],
                                    ["q", "qd", "theta", "gains", "u_p"], ["u"]),
            # the two laws' parts (_yielding_laws): u = u_ff + share u_fb
            f"feedback_{d}": ca.Function(f"feedback_{d}", [q, qd, theta, gains], list(full),
                                         ["q", "qd", "theta", "gains"],
                                         ["u_ff", "u_fb", "share"]),
            f"hfeedback_{d}": ca.Function(f"hfeedback_{d}", [q, qd, theta, gains, u_p],
                                          list(human), ["q", "qd", "theta", "gains", "u_p"],
                                          ["u_ff", "u_fb", "share"]),
        }
        #: hip progress (m) over the reference frame of a configuration: the phase's numerator
        self.progress = ca.Function(f"progress_{d}", [q, qd], [progress, progress_dot],
                                    ["q", "qd"], ["p", "p_dot"])
        qdd_s = ca.SX.sym("qdd", nq)
        #: its second derivative (m/s^2) given the accelerations
        self.progress_rate = ca.Function(f"progress_rate_{d}", [q, qd, qdd_s],
                                         [Jp @ qdd_s + Jpdot_qd], ["q", "qd", "qdd"],
                                         ["p_ddot"])
        self._numeric: FunctionSet | None = None

    def numeric(self) -> FunctionSet:
        """The functions compiled to C (cached on disk) and bound to reusable buffers."""
        if self._numeric is None:
            name = f"{self.model.name}_vc_{self.domain}_m{self.degree}"
            self._numeric = FunctionSet([*self.functions.values(), self.progress], name)
        return self._numeric

    def phase(self, q: np.ndarray, theta: np.ndarray) -> float:
        """tau of the configuration q (nq,) for the packed gait ``theta``."""
        return float(self.numeric()[f"phase_{self.domain}"](q, theta)[0].item())

    def phase_function(self, theta: np.ndarray) -> Callable[[np.ndarray], float]:
        """q (or a state x, q first) -> tau for the gait ``theta`` (the simulator's)."""
        f, nq, th = self.numeric()[f"phase_{self.domain}"], self.model.nq, np.array(theta)
        return lambda q: float(f(q[:nq], th)[0].item())


def virtual_constraints(model: HumanProsthesisModel, domain: str, degree: int
                        ) -> VirtualConstraints | ContactConstraints:
    """The virtual constraints of ``domain`` on ``model``'s graph: the paper's
    (:class:`~hp_model.outputs.VirtualConstraints`) or the multi-contact ones."""
    if model.graph == DomainGraph.PAPER:
        return VirtualConstraints(model, domain, degree)
    return ContactConstraints(model, domain, degree)
