"""Phase variable, virtual constraints and feedback linearization (paper Sec. IV-A, V).

Per domain v with stance knee th_sk and stance ankle th_sa (ps: th_pk, th_pa; pns: th_lk,
th_la):

    delta_p_hip(q) = c_k th_sk + c_a th_sa                (model.hip_progress_coefficients)
    tau(q)         = (delta_p_hip - p_min) / (p_max - p_min)
    y1(q, qd)      = d/dt delta_p_hip - v_hip            (relative degree 1)
    y2(q)          = y2_a(q) - B(tau(q); alpha)          (relative degree 2, 5 outputs)

y2_a are the joint angles other than the stance ankle, in the order of ``Y2_COORDS``.  The
outputs are symbolic in the gait parameters theta = (alpha row by row, v_hip, p_min, p_max),
so one object serves the regression, the optimizer, the simulator and the controllers.

Feedback linearization uses the domain's constrained dynamics qdd = a(q, qd) + b(q) u:

    A = [L_g y1; L_g L_f y2],  u = -A^-1 ([L_f y1; L_f^2 y2] + [eps y1; kp y2 + kd dy2])

so that dy1 = -eps y1 and ddy2 = -kp y2 - kd dy2 exactly.
"""

from __future__ import annotations

from dataclasses import dataclass

import casadi as ca
import numpy as np

from hp_model import bezier
from hp_model.compiled import FunctionSet
from hp_model.dynamics import constrained_accel, constraint_terms
from hp_model.human_prosthesis import HumanProsthesisModel

STANCE = {"ps": ("th_pk", "th_pa"), "pns": ("th_lk", "th_la")}
Y2_COORDS = {
    "ps": ("th_lh", "th_lk", "th_la", "th_rh", "th_pk"),
    "pns": ("th_lh", "th_lk", "th_rh", "th_pk", "th_pa"),
}
N_Y2 = 5
#: rows of the stacked outputs (y1, y2) the human's 4 torques control in each domain
HUMAN_OUTPUTS = {"ps": (1, 2, 3, 4), "pns": (0, 1, 2, 3)}


@dataclass(frozen=True)
class GaitParams:
    """Gait parameters of one domain: alpha (5, m+1) in rad, v_hip (m/s), p_min, p_max (m)."""

    alpha: np.ndarray
    v_hip: float
    p_min: float
    p_max: float

    def __post_init__(self) -> None:
        a = np.array(self.alpha, dtype=float)
        if a.ndim != 2 or a.shape[0] != N_Y2:
            raise ValueError(f"alpha must have shape (5, m+1), got {a.shape}")
        if not self.p_max > self.p_min:
            raise ValueError(f"p_max ({self.p_max}) must exceed p_min ({self.p_min})")
        a.setflags(write=False)
        object.__setattr__(self, "alpha", a)

    @property
    def degree(self) -> int:
        return self.alpha.shape[1] - 1

    def pack(self) -> np.ndarray:
        return np.r_[self.alpha.ravel(), self.v_hip, self.p_min, self.p_max]

    @classmethod
    def unpack(cls, theta: np.ndarray, degree: int) -> GaitParams:
        n = N_Y2 * (degree + 1)
        return cls(np.asarray(theta[:n]).reshape(N_Y2, degree + 1), float(theta[n]),
                   float(theta[n + 1]), float(theta[n + 2]))


def unpack_symbolic(theta, degree: int):
    """(alpha (5, m+1), v_hip, p_min, p_max) from a symbolic parameter vector."""
    n = N_Y2 * (degree + 1)
    alpha = ca.reshape(theta[:n], degree + 1, N_Y2).T
    return alpha, theta[n], theta[n + 1], theta[n + 2]


#: phase span over which the outputs come to rest past tau = 1 (VirtualConstraints)
TAIL = 0.15


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
    it cannot choose: the 4 human torques make the 4 human outputs (``HUMAN_OUTPUTS``: in ps
    the swing leg and stance hip angles, in pns y1 and the stance leg and prosthesis-side hip
    angles) follow their closed-loop dynamics; u = (u_h, u_p).
    """

    def __init__(self, model: HumanProsthesisModel, domain: str, degree: int = 5) -> None:
        if domain not in STANCE:
            raise ValueError(f"unknown domain '{domain}'")
        if degree < 1:
            raise ValueError("y2 needs a Bezier degree >= 1")
        self.model, self.domain, self.degree = model, domain, degree
        self.n_params = N_Y2 * (degree + 1) + 3
        ck, ca_ = model.hip_progress_coefficients(domain)
        self.c_knee, self.c_ankle = ck, ca_
        nq = model.nq
        idx = model.coord_names.index
        c = np.zeros(nq)
        c[idx(STANCE[domain][0])], c[idx(STANCE[domain][1])] = ck, ca_
        S = np.zeros((N_Y2, nq))
        for r, name in enumerate(Y2_COORDS[domain]):
            S[r, idx(name)] = 1.0
        self.c_row, self.S = c, S

        q, qd = model.q, model.qd
        theta = ca.SX.sym("theta", self.n_params)
        gains = ca.SX.sym("gains", 3)
        alpha, v_hip, p_min, p_max = unpack_symbolic(theta, degree)
        dp = p_max - p_min
        cD, SD = ca.DM(c).T, ca.DM(S)
        tau = (cD @ q - p_min) / dp
        tau_d = (cD @ qd) / dp
        # past tau = 1 (the designed touchdown) the curves come to rest instead of following
        # the polynomials' extrapolation (which swings the legs away from the ground): a
        # walker whose touchdown is late holds its end-of-step posture.  B(1) + B'(1) d
        # tanh((tau - 1)/d): position and velocity continuous at tau = 1, settled within a
        # few d (TAIL) of the phase
        tau_c = ca.fmin(tau, 1)
        th = ca.tanh(ca.fmax(tau - 1, 0) / TAIL)
        live = ca.if_else(tau < 1, 1, 0)
        B1 = bezier.evaluate(bezier.derivative(alpha), tau_c)
        Bd = bezier.evaluate(alpha, tau_c) + B1 * TAIL * th
        dB = B1 * (1 - th**2)
        ddB = (live * bezier.evaluate(bezier.derivative(bezier.derivative(alpha)), tau_c)
               - B1 * (2 / TAIL) * th * (1 - th**2))
        y1 = cD @ qd - v_hip
        y2 = SD @ q - Bd
        dy2 = SD @ qd - dB * tau_d

        # qdd = a + b u from the domain's constrained dynamics (affine in u)
        h = model.h[domain]
        J, Jdqd = constraint_terms(h, q, qd)
        qdd, _ = constrained_accel(model.D, model.H, ca.DM(model.B) @ model.u, J, Jdqd)
        b = ca.jacobian(qdd, model.u)
        a = ca.substitute(qdd, model.u, ca.DM.zeros(model.nu))
        M = SD - dB @ cD / dp  # d(dy2)/d(qdd)
        A = ca.vertcat(cD @ b, M @ b)
        Lf = ca.vertcat(cD @ a, M @ a - ddB * tau_d**2)
        v = ca.vertcat(gains[0] * y1, gains[1] * y2 + gains[2] * dy2)
        u = -ca.solve(A, Lf + v)
        # human side: rows of its outputs, columns of its torques; u_p is given
        u_p = ca.SX.sym("u_p", 2)
        rows = list(HUMAN_OUTPUTS[domain])
        A_h, A_p = A[rows, 0:4], A[rows, 4:6]
        u_h = -ca.solve(A_h, Lf[rows] + v[rows] + A_p @ u_p)
        u_hfl = ca.vertcat(u_h, u_p)
        # the same laws with the feedback term v given (a delayed human: hp_model.simulator)
        v_in = ca.SX.sym("v", 6)
        u_v = -ca.solve(A, Lf + v_in)
        vh_in = ca.SX.sym("v_h", len(rows))
        u_hv = ca.vertcat(-ca.solve(A_h, Lf[rows] + vh_in + A_p @ u_p), u_p)

        d = domain
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

    def posture(self, tau: float, params: GaitParams) -> np.ndarray:
        """The posture on the zero-dynamics surface (y2 = 0) at phase ``tau``: y2 joints from
        the Bezier curves, the stance ankle from delta_p_hip, the base placed so the stance
        foot is flat on the ground at x = 0."""
        q = np.zeros(self.model.nq)
        y2 = bezier.evaluate(params.alpha, tau)
        for name, val in zip(Y2_COORDS[self.domain], y2, strict=True):
            q[self.model.coord_names.index(name)] = val
        k, a = (self.model.coord_names.index(n) for n in STANCE[self.domain])
        p = params.p_min + tau * (params.p_max - params.p_min)
        q[a] = (p - self.c_knee * q[k]) / self.c_ankle
        return self.model.place_stance_foot(q, self.domain)
