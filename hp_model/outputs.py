"""Phase variable, virtual constraints and feedback linearization (paper Sec. IV-A, V).

The one owner of every formula about the walker's phase and outputs.  Per domain v with
stance knee th_sk and stance ankle th_sa (ps: th_pk, th_pa; pns: th_lk, th_la;
:mod:`hp_model.domains`):

    delta_p_hip(q) = c_k th_sk + c_a th_sa       (m; :class:`HipProgress`, the coefficients
                                                  from model.hip_progress_coefficients)
    tau(q)         = (delta_p_hip - p_min) / (p_max - p_min)                 (:func:`phase`)
    tau_dot        = d/dt delta_p_hip / (p_max - p_min)
    y1(q, qd)      = d/dt delta_p_hip - v_hip            (m/s, relative degree 1)
    y2(q)          = y2_a(q) - B(tau(q); alpha)          (rad, relative degree 2, 5 outputs)
    dy2            = d/dt y2_a - dB/dtau tau_dot,  ddy2 = d2/dt2 y2_a - d2B/dtau2 tau_dot^2
                     - dB/dtau tau_ddot                                     (:func:`outputs`)

y2_a are the joint angles other than the stance ankle, in the order of ``Domain.y2_coords``.  The
nominal posture at a phase puts the y2 joints on B(tau) and the stance ankle where
delta_p_hip = p_min + tau (p_max - p_min) (:func:`delta_p_at`, :meth:`HipProgress.ankle`).
The curve B is the gait's Bezier polynomial (:func:`plain`), continued linearly outside
[0, 1] for the prosthesis controllers (:func:`continued`) or brought to rest past tau = 1
for the simulated human (:func:`resting`).  The outputs are symbolic in the gait parameters
theta = (alpha row by row, v_hip, p_min, p_max) (:class:`ThetaLayout`), so one object serves
the regression, the optimizer, the simulator and the controllers; every formula here works
on numbers, numpy arrays and CasADi symbols alike (:func:`resting` on symbols only).

Feedback linearization uses the domain's constrained dynamics qdd = a(q, qd) + b(q) u:

    A = [L_g y1; L_g L_f y2],  u = -A^-1 ([L_f y1; L_f^2 y2] + [eps y1; kp y2 + kd dy2])

so that dy1 = -eps y1 and ddy2 = -kp y2 - kd dy2 exactly.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import casadi as ca
import numpy as np

from hp_model import bezier
from hp_model.compiled import FunctionSet
from hp_model.domains import N_Y2, Domain
from hp_model.dynamics import constrained_accel, constraint_terms
from hp_model.human_prosthesis import HumanProsthesisModel

#: a scalar or array of numbers, or a CasADi expression
Num = Any


# -- the packed gait vector -------------------------------------------------------------------
@dataclass(frozen=True)
class ThetaLayout:
    """Where the gait parameters of one domain sit in the packed vector theta =
    (alpha row by row (rows (m+1), rad), v_hip (m/s), p_min, p_max (m)), m the Bezier degree,
    ``rows`` the domain's y2 outputs (5 in the paper's domains; the multi-contact graph's
    domains have 4 to 6, :mod:`hp_model.contact_outputs`)."""

    degree: int
    rows: int = N_Y2

    def __post_init__(self) -> None:
        if self.degree < 0:
            raise ValueError(f"the Bezier degree must be >= 0, got {self.degree}")
        if self.rows < 1:
            raise ValueError(f"a gait has at least one output row, got {self.rows}")

    @classmethod
    def of_size(cls, size: int) -> ThetaLayout:
        """The layout of a packed vector of ``size`` entries."""
        m1, rest = divmod(size - 3, N_Y2)
        if rest or m1 < 1:
            raise ValueError(f"a gait vector has 5 (m + 1) + 3 entries, not {size}")
        return cls(m1 - 1)

    @property
    def n_alpha(self) -> int:
        return self.rows * (self.degree + 1)

    @property
    def size(self) -> int:
        return self.n_alpha + 3

    @property
    def alpha(self) -> slice:
        return slice(0, self.n_alpha)

    def row(self, r: int) -> slice:
        """The coefficients of y2 row ``r``."""
        m1 = self.degree + 1
        return slice(r * m1, (r + 1) * m1)

    @property
    def v_hip(self) -> int:
        return self.n_alpha

    @property
    def p_min(self) -> int:
        return self.n_alpha + 1

    @property
    def p_max(self) -> int:
        return self.n_alpha + 2

    @property
    def progress(self) -> slice:
        """(v_hip, p_min, p_max): the hip progress's parameters (the phase's and y1's)."""
        return slice(self.n_alpha, self.size)

    def unpack(self, theta: Num) -> tuple[Num, Num, Num, Num]:
        """(alpha (rows, m+1), v_hip, p_min, p_max) of a numeric or symbolic vector."""
        alpha: Num
        if isinstance(theta, ca.SX | ca.MX):
            alpha = ca.reshape(theta[self.alpha], self.degree + 1, self.rows).T
        else:
            alpha = np.asarray(theta)[self.alpha].reshape(self.rows, self.degree + 1)
        return alpha, theta[self.v_hip], theta[self.p_min], theta[self.p_max]


def unpack_symbolic(theta: Num, degree: int) -> tuple[Num, Num, Num, Num]:
    """(alpha (5, m+1), v_hip, p_min, p_max) from a symbolic parameter vector."""
    return ThetaLayout(degree).unpack(theta)


# -- the phase --------------------------------------------------------------------------------
def step_length(p_min: Num, p_max: Num) -> Num:
    """p_max - p_min (m): the hip's forward progress over the step."""
    return p_max - p_min


def phase(delta_p: Num, p_min: Num, p_max: Num, *rates: Num) -> Any:
    """tau = (delta_p_hip - p_min) / (p_max - p_min) (delta_p_hip, p_min, p_max in m); with
    time derivatives of delta_p_hip given (m/s, m/s^2, ...), the tuple (tau, and the same
    derivatives of tau (1/s, ...) = rate / (p_max - p_min))."""
    dp = step_length(p_min, p_max)
    tau = (delta_p - p_min) / dp
    return (tau, *(r / dp for r in rates)) if rates else tau


def phase_rate(delta_p_dot: Num, p_min: Num, p_max: Num) -> Num:
    """tau_dot (1/s) of a hip moving at delta_p_dot (m/s)."""
    return delta_p_dot / step_length(p_min, p_max)


def delta_p_at(tau: Num, p_min: Num, p_max: Num) -> Num:
    """delta_p_hip (m) at phase tau: the inverse of :func:`phase`."""
    return p_min + tau * step_length(p_min, p_max)


@dataclass(frozen=True)
class HipProgress:
    """delta_p_hip = c_k th_k + c_a th_a: the hip's forward position over the stance ankle
    (m), linearised, from the stance knee and ankle angles (rad) of a domain
    (``model.hip_progress_coefficients``); the same for their rates."""

    c_knee: float
    c_ankle: float

    @classmethod
    def of(cls, model: HumanProsthesisModel, domain: str) -> HipProgress:
        return cls(*model.hip_progress_coefficients(domain))

    def __call__(self, knee: Num, ankle: Num) -> Num:
        return self.c_knee * knee + self.c_ankle * ankle

    def ankle(self, delta_p: Num, knee: Num) -> Num:
        """The stance ankle angle that gives ``delta_p`` with the knee at ``knee``."""
        return (delta_p - self.c_knee * knee) / self.c_ankle

    def phase(self, knee: Num, ankle: Num, p_min: Num, p_max: Num) -> Num:
        """tau from the stance knee and ankle angles alone (what a prosthesis measures in
        its stance: the controllers' and the interaction model's phase)."""
        return phase(self(knee, ankle), p_min, p_max)

    def phase_function(self, p_min: float, p_max: float) -> Callable[[float, float], float]:
        """(knee, ankle) (rad) -> tau for the bounds (m), on Python floats: :meth:`phase`'s
        arithmetic in its order without its calls (a controller evaluates it every tick)."""
        ck, c_a = float(self.c_knee), float(self.c_ankle)
        lo, dp = float(p_min), float(step_length(p_min, p_max))
        return lambda knee, ankle: (ck * knee + c_a * ankle - lo) / dp


# -- the curves: (B, dB/dtau, d2B/dtau2) of the rows of alpha at tau --------------------------
Curve = Callable[[Num, Num], tuple[Num, Num, Num]]


def plain(alpha: Num, tau: Num) -> tuple[Num, Num, Num]:
    """The Bezier polynomials themselves (the optimizer's, on tau in [0, 1])."""
    d1 = bezier.derivative(alpha)
    return bezier.evaluate(alpha, tau), bezier.evaluate(d1, tau), \
        bezier.evaluate(bezier.derivative(d1), tau)


def continued(alpha: Num, tau: Num) -> tuple[Num, Num, Num]:
    """Continued linearly outside [0, 1] (:func:`hp_model.bezier.evaluate_continued`): the
    prosthesis controllers'."""
    return bezier.evaluate_continued(alpha, tau)


def continued_smoothly(alpha: Num, tau: Num) -> tuple[Num, Num, Num]:
    """Continued outside [0, 1] by the curves' second-order Taylor polynomial at the nearer
    end (C^2: :func:`hp_model.bezier.evaluate_continued` of order 2): past the end of a
    double support the accelerations the curves ask for, and so the contact forces, go on
    without a jump (continued linearly, a landing 1 ms late made the trailing toe pull
    0.4 kN on the ground)."""
    return bezier.evaluate_continued(alpha, tau, order=2)


#: phase span over which the outputs come to rest past tau = 1 (:func:`resting`)
TAIL = 0.15


def resting(alpha: Num, tau: Num) -> tuple[Num, Num, Num]:
    """Past tau = 1 (the designed touchdown) the curves come to rest instead of following the
    polynomials' extrapolation (which swings the legs away from the ground): a walker whose
    touchdown is late holds its end-of-step posture.  B(1) + B'(1) d tanh((tau - 1)/d):
    position and velocity continuous at tau = 1, settled within a few d (``TAIL``) of the
    phase.  The simulated human's curves (symbolic tau)."""
    tau_c = ca.fmin(tau, 1)
    th = ca.tanh(ca.fmax(tau - 1, 0) / TAIL)
    live = ca.if_else(tau < 1, 1, 0)
    B1 = bezier.evaluate(bezier.derivative(alpha), tau_c)
    B = bezier.evaluate(alpha, tau_c) + B1 * TAIL * th
    dB = B1 * (1 - th**2)
    ddB = (live * bezier.evaluate(bezier.derivative(bezier.derivative(alpha)), tau_c)
           - B1 * (2 / TAIL) * th * (1 - th**2))
    return B, dB, ddB


@dataclass(frozen=True)
class Outputs:
    """The phase, the outputs and their derivatives (module docstring), and the curve's
    (b, db, ddb) = (B, dB/dtau, d2B/dtau2) at tau.  The second derivatives only when the
    accelerations were given."""

    tau: Num
    tau_dot: Num
    y1: Num
    y2: Num
    dy2: Num
    b: Num
    db: Num
    ddb: Num
    tau_ddot: Num = None
    dy1: Num = None
    ddy2: Num = None


@dataclass(frozen=True)
class GaitTerms:
    """The four terms of a domain's gait as :func:`outputs` takes them, numbers or CasADi
    expressions: the curves' coefficients ``alpha`` (one row per output, m+1 columns, rad),
    v_hip (m/s), p_min and p_max (m) (:class:`GaitParams`, unchecked and unpacked)."""

    alpha: Num
    v_hip: Num
    p_min: Num
    p_max: Num


def outputs(y2_a: Num, y2_a_dot: Num, delta_p: Num, delta_p_dot: Num, gait: GaitTerms,
            curve: Curve = plain, *, y2_a_ddot: Num = None,
            delta_p_ddot: Num = None) -> Outputs:
    """The outputs (module docstring) of joint angles ``y2_a`` (the rows of ``gait.alpha``)
    and hip progress ``delta_p``, with their time derivatives (and, optionally,
    accelerations)."""
    p_min, p_max = gait.p_min, gait.p_max
    if delta_p_ddot is None:
        tau, tau_dot = phase(delta_p, p_min, p_max, delta_p_dot)
        tau_ddot = None
    else:
        tau, tau_dot, tau_ddot = phase(delta_p, p_min, p_max, delta_p_dot, delta_p_ddot)
    B, dB, ddB = curve(gait.alpha, tau)
    y1 = delta_p_dot - gait.v_hip
    y2 = y2_a - B
    dy2 = y2_a_dot - dB * tau_dot
    ddy2 = None if y2_a_ddot is None else y2_a_ddot - ddB * tau_dot**2 - dB * tau_ddot
    return Outputs(tau, tau_dot, y1, y2, dy2, B, dB, ddB, tau_ddot, delta_p_ddot, ddy2)


def stance_outputs(hip: HipProgress, x: Num, alpha: Num, v_hip: Num, p_min: Num, p_max: Num,
                   accel: Num = None) -> Outputs:
    """The paper's prosthesis outputs at x = (th_k, th_a, dth_k, dth_a) of the stance knee
    and ankle: tau and tau_dot from them alone, y1 = c_k dth_k + c_a dth_a - v_hip* (m/s),
    y2 = th_k - B_k(tau) (rad), dy2 (rad/s), with B_k (``alpha``: the knee's row) continued
    linearly outside [0, 1]; with ``accel`` = (ddth_k, ddth_a) also dy1, ddy2.  What the
    controllers and the model-error characterisation use (symbolic or numeric)."""
    th, dth = x[0:2], x[2:4]
    acc = {} if accel is None else {"y2_a_ddot": accel[0],
                                    "delta_p_ddot": hip(accel[0], accel[1])}
    return outputs(th[0], dth[0], hip(th[0], th[1]), hip(dth[0], dth[1]),
                   GaitTerms(alpha, v_hip, p_min, p_max), continued, **acc)


# -- gait parameters ----------------------------------------------------------------------------
@dataclass(frozen=True)
class GaitParams:
    """Gait parameters of one domain: alpha (rows, m+1) in rad (5 rows in the paper's
    domains), v_hip (m/s), p_min, p_max (m)."""

    alpha: np.ndarray
    v_hip: float
    p_min: float
    p_max: float

    def __post_init__(self) -> None:
        a = np.array(self.alpha, dtype=float)
        if a.ndim != 2 or a.shape[0] < 1 or a.shape[1] < 1:
            raise ValueError(f"alpha must have shape (rows, m+1), got {a.shape}")
        if not self.p_max > self.p_min:
            raise ValueError(f"p_max ({self.p_max}) must exceed p_min ({self.p_min})")
        a.setflags(write=False)
        object.__setattr__(self, "alpha", a)

    @property
    def degree(self) -> int:
        return self.alpha.shape[1] - 1

    @property
    def layout(self) -> ThetaLayout:
        return ThetaLayout(self.degree, self.alpha.shape[0])

    def pack(self) -> np.ndarray:
        return np.r_[self.alpha.ravel(), self.v_hip, self.p_min, self.p_max]

    @classmethod
    def unpack(cls, theta: np.ndarray, degree: int | None = None) -> GaitParams:
        """The parameters of a packed vector (of ``degree``, default: from its size)."""
        L = ThetaLayout(degree) if degree is not None else ThetaLayout.of_size(len(theta))
        alpha, v_hip, p_min, p_max = L.unpack(np.asarray(theta)[:L.size])
        return cls(alpha, float(v_hip), float(p_min), float(p_max))

    def phase_of(self, delta_p: Num) -> Num:
        """tau of a hip progress delta_p_hip (m)."""
        return phase(delta_p, self.p_min, self.p_max)

    def delta_p_at(self, tau: Num) -> Num:
        """delta_p_hip (m) at phase tau."""
        return delta_p_at(tau, self.p_min, self.p_max)

    @property
    def step_length(self) -> float:
        """p_max - p_min (m): the hip's forward progress over the step."""
        return step_length(self.p_min, self.p_max)

    @property
    def nominal_rate(self) -> float:
        """tau_dot (1/s) of the hip moving at v_hip (y1 = 0)."""
        return phase_rate(self.v_hip, self.p_min, self.p_max)

    @property
    def nominal_duration(self) -> float:
        """(p_max - p_min) / v_hip (s): the step's duration at the nominal hip velocity."""
        return self.step_length / self.v_hip


def as_params(theta: GaitParams | np.ndarray, degree: int) -> GaitParams:
    """Gait parameters given as such or packed."""
    return theta if isinstance(theta, GaitParams) else GaitParams.unpack(theta, degree)


class VirtualConstraints:
    """Phase variable, outputs and feedback linearization of one domain of the 12-DOF model.

    Symbolic functions (``self.functions``), named with the domain suffix:

        phase_<d>(q, theta)               -> tau
        outputs_<d>(q, qd, theta)         -> y1, y2, dy2, tau
        fl_<d>(q, qd, theta, gains)       -> u, y1, y2, dy2, tau     gains = (eps, kp, kd)
        hfl_<d>(q, qd, theta, gains, u_p) -> u                       human side only
        flv_<d>(q, qd, theta, v)          -> u    fl with the feedback term v (6) given
        hflv_<d>(q, qd, theta, v_h, u_p)  -> u    hfl with the human rows' v_h (4) given

    ``hfl`` is the human's feedback linearization given the prosthesis motor torque u_p (2,)
    it cannot choose: the 4 human torques make the 4 human outputs (``Domain.human_outputs``: in ps
    the swing leg and stance hip angles, in pns y1 and the stance leg and prosthesis-side hip
    angles) follow their closed-loop dynamics; u = (u_h, u_p).  The simulated human's curves
    come to rest past tau = 1 (:func:`resting`).

    Symbolic expressions: :meth:`output_exprs` (any curve, with accelerations),
    :meth:`on_outputs` and :meth:`posture_exprs`; numeric: :meth:`phase`,
    :meth:`phase_rate`, :meth:`posture`, :meth:`posture_rate`.
    """

    def __init__(self, model: HumanProsthesisModel, domain: str, degree: int = 5) -> None:
        domain = Domain(domain)
        if degree < 1:
            raise ValueError("y2 needs a Bezier degree >= 1")
        self.model, self.domain, self.degree = model, domain, degree
        self.layout = ThetaLayout(degree)
        self.n_params = self.layout.size
        self.roles = model.roles[domain]
        self.hip = HipProgress.of(model, domain)
        nq = model.nq
        c = np.zeros(nq)
        c[self.roles.knee], c[self.roles.ankle] = self.hip.c_knee, self.hip.c_ankle
        S = np.zeros((N_Y2, nq))
        for r, i in enumerate(self.roles.y2):
            S[r, i] = 1.0
        self.c_row, self.S = c, S  # d delta_p_hip / dq (1/m... m/rad), y2_a = S q

        q, qd = model.q, model.qd
        theta = ca.SX.sym("theta", self.n_params)
        gains = ca.SX.sym("gains", 3)
        o = self.output_exprs(q, qd, theta)
        _, _, p_min, p_max = self.layout.unpack(theta)
        dp = step_length(p_min, p_max)
        cD, SD = ca.DM(c).T, ca.DM(S)

        # qdd = a + b u from the domain's constrained dynamics (affine in u)
        h = model.h[domain]
        J, Jdqd = constraint_terms(h, q, qd)
        qdd, _ = constrained_accel(model.D, model.H, ca.DM(model.B) @ model.u, J, Jdqd)
        b = ca.jacobian(qdd, model.u)
        a = ca.substitute(qdd, model.u, ca.DM.zeros(model.nu))
        M = SD - o.db @ cD / dp  # d(dy2)/d(qdd)
        A = ca.vertcat(cD @ b, M @ b)
        Lf = ca.vertcat(cD @ a, M @ a - o.ddb * o.tau_dot**2)
        v = ca.vertcat(gains[0] * o.y1, gains[1] * o.y2 + gains[2] * o.dy2)
        u = -ca.solve(A, Lf + v)
        # human side: rows of its outputs, columns of its torques; u_p is given
        u_p = ca.SX.sym("u_p", 2)
        rows = list(domain.human_outputs)
        A_h, A_p = A[rows, 0:4], A[rows, 4:6]
        u_h = -ca.solve(A_h, Lf[rows] + v[rows] + A_p @ u_p)
        u_hfl = ca.vertcat(u_h, u_p)
        # the same laws with the feedback term v given (a delayed human: hp_model.simulator)
        v_in = ca.SX.sym("v", 6)
        u_v = -ca.solve(A, Lf + v_in)
        vh_in = ca.SX.sym("v_h", len(rows))
        u_hv = ca.vertcat(-ca.solve(A_h, Lf[rows] + vh_in + A_p @ u_p), u_p)

        d = domain
        y1, y2, dy2, tau = o.y1, o.y2, o.dy2, o.tau
        self.functions = {
            f"phase_{d}": ca.Function(f"phase_{d}", [q, theta], [tau], ["q", "theta"], ["tau"]),
            f"outputs_{d}": ca.Function(f"outputs_{d}", [q, qd, theta], [y1, y2, dy2, tau],
                                        ["q", "qd", "theta"], ["y1", "y2", "dy2", "tau"]),
            f"fl_{d}": ca.Function(f"fl_{d}", [q, qd, theta, gains], [u, y1, y2, dy2, tau],
                                   ["q", "qd", "theta", "gains"],
                                   ["u", "y1", "y2", "dy2", "tau"]),
            f"hfl_{d}": ca.Function(f"hfl_{d}", [q, qd, theta, gains, u_p], [u_hfl],
                                    ["q", "qd", "theta", "gains", "u_p"], ["u"]),
            f"flv_{d}": ca.Function(f"flv_{d}", [q, qd, theta, v_in], [u_v],
                                    ["q", "qd", "theta", "v"], ["u"]),
            f"hflv_{d}": ca.Function(f"hflv_{d}", [q, qd, theta, vh_in, u_p], [u_hv],
                                     ["q", "qd", "theta", "v_h", "u_p"], ["u"]),
        }
        self._numeric: FunctionSet | None = None

    def numeric(self) -> FunctionSet:
        """The functions compiled to C (cached on disk) and bound to reusable buffers."""
        if self._numeric is None:
            name = f"{self.model.name}_vc_{self.domain}_m{self.degree}"
            self._numeric = FunctionSet(list(self.functions.values()), name)
        return self._numeric

    # -- symbolic -------------------------------------------------------------------------
    def output_exprs(self, q: Num, qd: Num, theta: Num, qdd: Num = None,
                     curve: Curve = resting) -> Outputs:
        """The outputs and their derivatives (second ones with ``qdd``) of the walker at
        (q, qd) for the packed gait ``theta``, on ``curve`` (default the simulated human's);
        symbolic."""
        gait = GaitTerms(*self.layout.unpack(theta))
        k, a = self.roles.knee, self.roles.ankle
        S = ca.DM(self.S)
        acc = {} if qdd is None else {"y2_a_ddot": S @ qdd,
                                      "delta_p_ddot": self.hip(qdd[k], qdd[a])}
        return outputs(S @ q, S @ qd, self.hip(q[k], q[a]), self.hip(qd[k], qd[a]), gait,
                       curve, **acc)

    def on_outputs(self, q: Num, qd: Num, theta: Num) -> tuple[Num, Num, Num]:
        """(q, qd, tau): the stance knee and ankle (and the prosthesis joints) of (q, qd)
        set the phase tau and its rate; the other y2 joints (``roles.on_outputs``) are put
        on their Bezier curves B(tau), their rates dB/dtau tau_dot; every other coordinate
        is kept.  Symbolic (the base is not placed: :mod:`hp_model.placement`)."""
        alpha, _v_hip, p_min, p_max = self.layout.unpack(theta)
        r = self.roles
        tau, tau_d = phase(self.hip(q[r.knee], q[r.ankle]), p_min, p_max,
                           self.hip(qd[r.knee], qd[r.ankle]))
        B, dB, _ = plain(alpha, tau)
        q_out = [q[i] for i in range(self.model.nq)]
        qd_out = [qd[i] for i in range(self.model.nq)]
        for i, row in zip(r.on_outputs, r.on_outputs_rows, strict=True):
            q_out[i], qd_out[i] = B[row], dB[row] * tau_d
        return ca.vertcat(*q_out), ca.vertcat(*qd_out), tau

    def posture_exprs(self, tau: Num, tau_dot: Num, theta: Num) -> tuple[Num, Num]:
        """The joints (q, qd) of the nominal posture at phase tau moving at tau_dot (1/s):
        the y2 joints on B(tau), the stance ankle at delta_p_hip = :func:`delta_p_at` (tau),
        the rates d/dtau of those times tau_dot; base and socket zero.  Symbolic (the base is
        not placed: :mod:`hp_model.placement`)."""
        alpha, _v_hip, p_min, p_max = self.layout.unpack(theta)
        return self._posture(tau, tau_dot, alpha, p_min, p_max, plain,
                             lambda v: ca.vertcat(*v))

    def nominal_rate(self, theta: Num) -> Num:
        """tau_dot (1/s) of the hip moving at the gait's v_hip; symbolic."""
        _, v_hip, p_min, p_max = self.layout.unpack(theta)
        return phase_rate(v_hip, p_min, p_max)

    def _posture(self, tau: Num, tau_dot: Num, alpha: Num, p_min: Num, p_max: Num,
                 curve: Curve, stack: Callable[[list], Num]) -> tuple[Num, Num]:
        r = self.roles
        B, dB, _ = curve(alpha, tau)
        q: list = [0.0] * self.model.nq
        dq: list = [0.0] * self.model.nq  # d(posture)/dtau
        for row, i in enumerate(r.y2):
            q[i], dq[i] = B[row], dB[row]
        q[r.ankle] = self.hip.ankle(delta_p_at(tau, p_min, p_max), q[r.knee])
        dq[r.ankle] = self.hip.ankle(step_length(p_min, p_max), dq[r.knee])
        return stack(q), stack([v * tau_dot for v in dq])

    # -- numeric --------------------------------------------------------------------------
    def _progress(self, theta: GaitParams | np.ndarray) -> tuple[float, float, float]:
        """(v_hip, p_min, p_max) of gait parameters given as such or packed."""
        if isinstance(theta, GaitParams):
            return theta.v_hip, theta.p_min, theta.p_max
        L = self.layout
        return theta[L.v_hip], theta[L.p_min], theta[L.p_max]

    def phase(self, q: np.ndarray, theta: GaitParams | np.ndarray) -> Num:
        """tau of the configuration(s) q ((nq,) or (nq, n)); the same arithmetic as the
        generated ``phase_<d>``."""
        _, p_min, p_max = self._progress(theta)
        return phase(self.hip(q[self.roles.knee], q[self.roles.ankle]), p_min, p_max)

    def phase_function(self, theta: GaitParams | np.ndarray) -> Callable[[np.ndarray], float]:
        """q (nq,) -> tau for the gait ``theta``, on Python floats: :meth:`phase`'s
        arithmetic, in its order (so the generated ``phase_<d>`` agrees bit for bit), at a
        third of its cost (the simulator evaluates it several times per period)."""
        _, p_min, p_max = (float(v) for v in self._progress(theta))
        ck, c_a = float(self.hip.c_knee), float(self.hip.c_ankle)
        k, a = self.roles.knee, self.roles.ankle
        dp = step_length(p_min, p_max)
        return lambda q: (ck * float(q[k]) + c_a * float(q[a]) - p_min) / dp

    def phase_rate(self, qd: np.ndarray, theta: GaitParams | np.ndarray) -> Num:
        """tau_dot (1/s) of the velocities qd ((nq,) or (nq, n))."""
        _, p_min, p_max = self._progress(theta)
        return phase_rate(self.hip(qd[self.roles.knee], qd[self.roles.ankle]), p_min, p_max)

    def stance_phase(self, knee: Num, ankle: Num, theta: GaitParams | np.ndarray) -> Num:
        """tau from the stance knee and ankle angles alone (:meth:`HipProgress.phase`)."""
        _, p_min, p_max = self._progress(theta)
        return self.hip.phase(knee, ankle, p_min, p_max)

    def posture(self, tau: float, theta: GaitParams | np.ndarray) -> np.ndarray:
        """The posture on the zero-dynamics surface (y2 = 0) at phase ``tau``
        (:meth:`posture_exprs`), the base placed so the stance foot is flat on the ground at
        x = 0 (:meth:`hp_model.hybrid.HybridModel.place_stance_foot`)."""
        p = as_params(theta, self.degree)
        q, _ = self._posture(tau, 0.0, p.alpha, p.p_min, p.p_max, plain, np.array)
        return self.model.place_stance_foot(q, self.domain)

    def posture_rate(self, tau: float, tau_dot: float, theta: GaitParams | np.ndarray
                     ) -> np.ndarray:
        """The velocity of the posture at ``tau`` moving at ``tau_dot`` (1/s): the joints'
        d(posture)/dtau tau_dot, the base's solving J_foot qd = 0 (the stance foot at rest;
        :meth:`hp_model.hybrid.HybridModel.stance_state`)."""
        p = as_params(theta, self.degree)
        q, qd = self._posture(tau, tau_dot, p.alpha, p.p_min, p.p_max, plain, np.array)
        return self.model.stance_state(q, qd, self.domain)[1]

