"""Symbolic controller terms, built once from the prosthesis subsystem and compiled to C.

Every per-tick model evaluation of every controller is ONE call of a generated-C function
(:class:`hp_model.compiled.FunctionSet`, preallocated buffers).  Gait, tube and gains enter
as a numeric parameter vector ``p``, so the compiled library depends only on the Bezier
degrees and is cached on disk across runs.

Functions (x = x_p = (th_pk, th_pa, dth_pk, dth_pa)):

``clf_qp(x, p)`` -- the robust CLF-QP of paper Sec. V.  With the reduced dynamics
x_dot = f_p + g_m u + g_s F_s (:class:`hp_model.ProsthesisSubsystem`, ``reduced``):

    tau, eta = (y1, y2, dy2)   the paper's prosthesis outputs of the stance knee and ankle
             (:func:`hp_model.outputs.stance_outputs`: tau from th_pk, th_pa alone,
             y1 = c_k dth_pk + c_a dth_pa - v_hip*, y2 = th_pk - B_pk(tau), B_pk continued
             linearly outside tau in [0, 1])
    nu     = Lf + Am u + As F_s   (Lf = [L_f y1; L_f^2 y2], Am = [L_gm y1; L_gm L_f y2], ...)
    V      = eta^T P_eps eta,  LFV = eta^T (P_eps F + F^T P_eps) eta,  LGV = 2 eta^T P_eps G
    robust CLF row over the box F_s in [c - r, c + r] (REFERENCE.md Sec. 2):
        (LGV Am) u - (gamma/eps) rho <= -(gamma/eps) V - LFV - LGV Lf - a^T c - |a|^T r,
        a = As^T LGV^T
    cost   |nu(u, F*)|^2 + c_rho rho = u^T H u + 2 b^T u + c_rho rho + const,
           H = Am^T Am, b = Am^T (Lf + As F*)

  and returns it in solver form for z = (u_k, u_a, rho): min 1/2 z^T Pu z + cu^T z,
  Gu z <= hu, with the cost divided by trace(H) and the row by its norm (both only condition
  the problem; the minimiser is unchanged).  The exact QP (no rho) is the (u, u) block.

``stance_ref(tau, rate, p)`` -- the nominal stance joint trajectory at a phase tau moving at
``rate`` (1/s): th_pk = B_pk(tau), th_pa where delta_p_hip is the phase's
(:func:`hp_model.outputs.delta_p_at`, :meth:`hp_model.outputs.HipProgress.ankle`), and their
first and second time derivatives.

``swing_ref(x, s_raw, rate_raw, p)`` -- the swing target at the unclipped time phase
s_raw = (t - t_liftoff) / T_pns (rate_raw = 1 / T_pns): the pns Bezier rows of th_pk, th_pa
at tau = clip(s_raw, 0, 1) plus the landing offset, its time derivatives, the gravity torque
(joint side) of the prosthesis hanging from a socket at the nominal pitch theta_s(tau) (a
Bezier fit of the pns collocation trajectory), and tau.  Landing: from ``landing_start``
on, about the Bezier posture with the socket at theta_s(tau), the knee turns the shank
toward the vertical under the knee by the fraction w = clip(landing_reach (s_raw -
landing_start) / (1 - landing_start), 0, 1) of its angle (the lowest the sole gets at a fixed
foot pitch; the reach keeps growing past tau = 1 when the touchdown is late) and the ankle
turns the foot flat in the world over the next landing_flatten of the phase.  The nominal
gait's swing foot skims the ground over the last part of pns and touches it tangentially,
so a controller that cannot sense the human's phase must reach for the ground to land.

``phase_pd(x, p)`` -- the phase-PD reference law on the same state-based phase and outputs
as the CLF-QP: the gait's nominal stance motor torque u*(tau) (a Bezier fit of the ps
collocation trajectory, ``feedforward``) and the joint-side feedback
(-kp y2 - kd dy2, k_vhip y1) (knee, ankle).

``passive(x, tau, rate, p)`` -- Spong's robust passivity-based law (REFERENCE.md Sec. 2) on
the 2-DOF stance prosthesis (foot fixed, socket force ignored), JOINT torque out:

    e = q - q_d, v = qd_d - L e, a = qdd_d - L e_dot, r = e_dot + L e,
    u = Y(q, qd, a, v) (theta0 + dtheta) - K r,  dtheta = -rho Y^T r / max(|Y^T r|, eps_b)

  The robust term covers the links' standard parameters; the drives' armature (on a device
  with rotor inertia, the last parameters) is taken as known.  ``passive_ref(x, ref, p)`` is
  the same law about a reference given as (q_d, qd_d, qdd_d): the multi-contact graph's
  ``passive`` (:class:`prosthesis_controller.passive.ContactPassive`).

  M, C (Christoffel form), g are the reduced Lagrangian's: M = Phi^T D Phi with
  Phi = d q_emb / d q_joint of the flat-foot embedding; the regressor Y is linear in the
  standard parameters (m, m c_x, m c_z, I_o) of each link, obtained by AD from copies of the
  SAME tree with one unit parameter set per link (no second hand-written model).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence

import casadi as ca
import numpy as np

from hp_model import bezier
from hp_model.compiled import CompileBackend, FunctionSet
from hp_model.domains import Domain
from hp_model.dynamics import mass_matrix_and_bias
from hp_model.interaction import InteractionModel
from hp_model.outputs import HipProgress, delta_p_at, stance_outputs, step_length
from hp_model.prosthesis import ProsthesisSubsystem
from hp_model.tree import PlanarTree, frame_pose

F_OUT = np.array([[0.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, 0.0, 0.0]])
G_OUT = np.array([[1.0, 0.0], [0.0, 0.0], [0.0, 1.0]])


class Layout:
    """A named, ordered parameter vector: symbols for building, packing for numbers."""

    def __init__(self) -> None:
        self._items: list[tuple[str, tuple[int, ...], ca.SX]] = []

    def add(self, name: str, shape: tuple[int, ...] = ()) -> ca.SX:
        """A symbol of ``shape``; matrices are packed row by row (numpy C order)."""
        n = int(np.prod(shape)) if shape else 1
        s = ca.SX.sym(name, n)
        self._items.append((name, shape, s))
        if len(shape) == 2:
            return ca.reshape(s, shape[1], shape[0]).T
        return s

    def offset(self, name: str) -> int:
        """Index of the first element of ``name`` in the packed vector."""
        k = 0
        for n, _, s in self._items:
            if n == name:
                return k
            k += s.numel()
        raise KeyError(f"no parameter '{name}' in the layout")

    @property
    def symbol(self) -> ca.SX:
        return ca.vertcat(*[s for _, _, s in self._items])

    @property
    def size(self) -> int:
        return sum(s.numel() for _, _, s in self._items)

    def pack(self, **values: object) -> np.ndarray:
        missing = {n for n, _, _ in self._items} - set(values)
        extra = set(values) - {n for n, _, _ in self._items}
        if missing or extra:
            raise ValueError(f"parameter layout: missing {sorted(missing)}, "
                             f"unexpected {sorted(extra)}")
        out = []
        for name, shape, s in self._items:
            a = np.asarray(values[name], dtype=float).reshape(-1)
            if a.size != s.numel():
                raise ValueError(f"parameter '{name}': expected shape {shape}, got {a.size}")
            out.append(a)
        return np.concatenate(out)


def reduced_lagrangian(sub: ProsthesisSubsystem, tree: PlanarTree | None = None
                       ) -> tuple[ca.SX, ca.SX, ca.SX, ca.SX]:
    """(q_j, M(q_j), g(q_j), Christoffel C(q_j, qd_j)) of the stance prosthesis (foot flat
    at the origin), in the joint coordinates q_j = (th_pk, th_pa), for ``tree`` (default the
    subsystem's own) with the subsystem's embedding."""
    tree = tree or sub.tree
    qj = ca.SX.sym("qj", 2)
    qdj = ca.SX.sym("qdj", 2)
    x = ca.vertcat(qj, ca.SX.zeros(2))
    q_emb = sub.functions["embed"](x)[0]
    Phi = ca.jacobian(q_emb, qj)
    q, qd = sub.q, sub.qd
    D, H = mass_matrix_and_bias(tree, q, qd)
    grav = ca.substitute(H, qd, ca.SX.zeros(sub.nq))
    D_e = ca.substitute(D, q, q_emb)
    M = Phi.T @ D_e @ Phi
    g = Phi.T @ ca.substitute(grav, q, q_emb)
    C = ca.SX.zeros(2, 2)
    dM = [ca.jacobian(M[:, k], qj) for k in range(2)]  # dM[k][i, j] = dM_ik / dq_j
    for i in range(2):
        for j in range(2):
            for k in range(2):
                cijk = 0.5 * (dM[j][i, k] + dM[k][i, j] - dM[k][j, i])
                C[i, j] += cijk * qdj[k]
    return ca.vertcat(qj, qdj), M, g, C


UNIT_SETS = (  # (mass, com, inertia about com) -> standard parameters (m, m cx, m cz, I_o)
    (1.0, (0.0, 0.0), 0.0),  # -> (1, 0, 0, 0)
    (1.0, (1.0, 0.0), 0.0),  # -> (1, 1, 0, 1)
    (1.0, (0.0, 1.0), 0.0),  # -> (1, 0, 1, 1)
    (0.0, (0.0, 0.0), 1.0),  # -> (0, 0, 0, 1)
)


def standard_parameters(tree: PlanarTree, bodies: Sequence[str]) -> np.ndarray:
    """theta0: (m, m c_x, m c_z, I_com + m |c|^2) of each named body, stacked, then the
    armature (kg m^2) of each driven joint (:func:`drives`)."""
    out = []
    for name in bodies:
        b = tree.body(name)
        cx, cz = b.com
        out += [b.mass, b.mass * cx, b.mass * cz, b.inertia + b.mass * (cx * cx + cz * cz)]
    return np.array(out + [tree.body(n).armature for n in drives(tree)])


def drives(tree: PlanarTree) -> list[str]:
    """The bodies whose joint carries an armature (a drive's reflected rotor inertia)."""
    return [b.name for b in tree.bodies if b.armature > 0]


def regressor(sub: ProsthesisSubsystem, xa: ca.SX, a: ca.SX, v: ca.SX
              ) -> tuple[ca.SX, list[str]]:
    """Y (2 x 4 n_links) with Y theta = M a + C(q, qd) v + g for the moving links (the foot is
    fixed in stance and drops out).  ``xa`` = (q_j, qd_j) symbol to express Y in."""
    links = [b.name for b in sub.tree.bodies if b.name != "p_foot"]

    def column(name: str, **unit: object) -> ca.SX:
        """M a + C v + g of the tree with only ``name``'s parameters set to ``unit``."""
        bodies = tuple(
            dataclasses.replace(b, **unit) if b.name == name  # type: ignore[arg-type]
            else dataclasses.replace(b, mass=0.0, inertia=0.0, armature=0.0)
            for b in sub.tree.bodies)
        tree = PlanarTree(bodies=bodies, frames=sub.tree.frames, gravity=sub.tree.gravity)
        xs, M, g, C = reduced_lagrangian(sub, tree)
        return ca.substitute(M @ a + C @ v + g, xs, xa)

    cols: list[ca.SX] = []
    for name in links:
        y1, y2, y3, y4 = (column(name, mass=mass, com=com, inertia=inertia, armature=0.0)
                          for mass, com, inertia in UNIT_SETS)
        cols += [y1, y2 - y1 - y4, y3 - y1 - y4, y4]
    cols += [column(name, mass=0.0, inertia=0.0, armature=1.0) for name in drives(sub.tree)]
    return ca.horzcat(*cols), links


#: the ``estimator`` output of :func:`clf_qp_loop_function`, in order
ESTIMATOR_TERMS = ("b0", "b1", "Jv00", "Jv01", "Jv10", "Jv11", "A00", "A01", "A10", "A11",
                   "lo0", "lo1", "hi0", "hi1", "in_range")
#: QP rows of :func:`clf_qp_loop_function`: the CLF row, then the stance-foot contact rows
LOOP_ROWS = ("clf", "friction_fwd", "friction_back", "normal_force", "cop_toe", "cop_heel")
#: units of the relaxations in the solver's variables: rho = LOOP_RHO_UNIT z[2], sigma =
#: LOOP_SIGMA_UNIT z[3].  They set how large the slacks' linear costs look to piqp: with rho
#: in units of rho_max (1e4) and sigma of sigma_max those were ~1e4 against torque costs of ~1,
#: and piqp needed 16 iterations (median; 160 at p99, 13 failures in 3000 ticks), in these
#: units 10 (11 at p99, none) on the demo subject's nominal stance
LOOP_RHO_UNIT = 100.0
LOOP_SIGMA_UNIT = 1.0


def clf_qp_loop_function(sub: ProsthesisSubsystem, degree: int, margin_degree: int
                         ) -> tuple[Layout, ca.Function]:
    """``clf_qp_loop(x, p)``: the interaction-aware robust CLF-QP (issue 17) in solver form.

    The model is the human-prosthesis loop restricted to the gait's nominal human
    (:mod:`hp_model.interaction`): x_dot = f_r + g_r u, foot wrench w = w0 + W u, both
    affine in the motor torque u.  With the paper's prosthesis outputs eta = (y1, y2, dy2)
    (:func:`stance_outputs`; y2 on the knee) and Jo = d(y1, dy2)/dx:

        nu = a + A u,  a = Jo f_r,  A = Jo g_r
        CLF row:  LGV A u - (gamma/eps) rho <= -(gamma/eps) V - LFV - LGV a
                                                - LGV c_d - |LGV| r_d
        contact:  F_x - mu F_z <= 0, -F_x - mu F_z <= 0, F_z >= f_min,
                  toe F_z + M_y >= 0, heel F_z - M_y >= 0      (w = w0 + W u; - sigma)
        cost:     |a + A u|^2 + c_rho rho + c_sigma sigma

    with [c_d - r_d, c_d + r_d] the characterised bound of what the nominal-human model does
    not explain, d = nu_true - (a + A u) (:mod:`characterization.tube.model_error`), a Bezier
    box over the
    phase s in [tau_lo, tau_hi], zero outside that range and when ``margin_gate`` is 0 (the
    controller sets it per tick: 0 within the excluded time after touchdown, whose transient
    is left to the relaxation; zero coefficients: no margin).  Outputs for the disturbance
    estimator, packed in one vector ``estimator`` (:data:`ESTIMATOR_TERMS`, read with one
    ``tolist``): b = Jo[:, 0:2] dth - a and Jv = Jo[:, 2:4] (row by row), so that a measured
    joint acceleration ddth gives d = b + Jv ddth - A u; A row by row; for the coverage
    monitor the bound itself (lower (2), upper (2), ungated) and 1 inside its phase range.
    Decision variables z = (u_k, u_a, rho / rho_scale, sigma /
    sigma_scale); each row is divided by the norm of its torque part, so sigma is the
    violation of a contact row in torque-equivalent units, and the cost by trace(A^T A).
    The exact form uses the (u, u) block and the first two columns of the rows."""
    full = sub.full
    inter = InteractionModel(full, degree)
    vc = inter.vc
    L = Layout()
    theta = L.add("theta", (inter.vc.n_params,))
    gains = L.add("gains", (3,))
    P_eps = L.add("P_eps", (3, 3))
    g_over_eps = L.add("gamma_over_eps")
    c_rho, rho_scale = L.add("c_rho"), L.add("rho_scale")
    c_sigma, sigma_scale = L.add("c_sigma"), L.add("sigma_scale")
    d_lo = L.add("margin_lower", (2, margin_degree + 1))
    d_hi = L.add("margin_upper", (2, margin_degree + 1))
    tau_lo, tau_hi = L.add("margin_tau_lo"), L.add("margin_tau_hi")
    gate = L.add("margin_gate")
    d_hat = L.add("d_hat", (2,))
    mu, f_min = L.add("mu"), L.add("f_min")
    toe, heel = L.add("toe"), L.add("heel")
    x = ca.SX.sym("x", 4)
    f_r, g_r, w0, W, _ = inter.functions["interaction_ps"](x, theta, gains)
    alpha, v_hip, p_min, p_max = vc.layout.unpack(theta)
    o = stance_outputs(vc.hip, x, alpha[vc.roles.prosthesis_rows[0], :], v_hip, p_min, p_max)
    tau = o.tau
    eta = ca.vertcat(o.y1, o.y2, o.dy2)
    Jo = ca.jacobian(ca.vertcat(o.y1, o.dy2), x)
    a, A = Jo @ f_r, Jo @ g_r
    F, G = ca.DM(F_OUT), ca.DM(G_OUT)
    V = eta.T @ P_eps @ eta
    LFV = eta.T @ (P_eps @ F + F.T @ P_eps) @ eta
    LGV = 2 * eta.T @ P_eps @ G  # type: ignore[operator]  # casadi's stubs: SX.T as Sparsity
    s = ca.fmin(ca.fmax((tau - tau_lo) / ca.fmax(tau_hi - tau_lo, 1e-9), 0), 1)
    lo, hi = bezier.evaluate(d_lo, s), bezier.evaluate(d_hi, s)
    in_range = (tau >= tau_lo) * (tau <= tau_hi)  # the bound's phase range
    on = gate * in_range  # gated in time (and off) by the controller
    c_d, r_d = on * 0.5 * (lo + hi), on * 0.5 * ca.fmax(hi - lo, 0)
    # the disturbance estimator's terms: nu = Jo (dth, ddth) = b + a + Jv ddth
    b_est = Jo[:, 0:2] @ x[2:4] - a
    Jv = Jo[:, 2:4]
    est = ca.vertcat(b_est, Jv[0, 0], Jv[0, 1], Jv[1, 0], Jv[1, 1], A[0, 0], A[0, 1],
                     A[1, 0], A[1, 1], lo, hi, in_range)
    a_c = a + d_hat  # the drift with the online estimate of the model error (0: off)
    h_clf = -g_over_eps * V - LFV - LGV @ a_c - LGV @ c_d - ca.fabs(LGV) @ r_d
    g_clf = LGV @ A
    fx0, fz0, my0 = w0[0], w0[1], w0[2]
    Wx, Wz, Wm = W[0, :], W[1, :], W[2, :]
    rows_u = [Wx - mu * Wz, -Wx - mu * Wz, -Wz, -(toe * Wz + Wm), -(heel * Wz - Wm)]
    rows_h = [mu * fz0 - fx0, mu * fz0 + fx0, fz0 - f_min, toe * fz0 + my0,
              heel * fz0 - my0]
    n_clf = ca.norm_2(ca.horzcat(g_clf, g_over_eps * rho_scale))
    G_rows = [ca.horzcat(g_clf, -g_over_eps * rho_scale, 0) / n_clf]
    h_rows = [h_clf / n_clf]
    for gu, hh in zip(rows_u, rows_h, strict=True):
        n = ca.norm_2(gu) + 1e-12
        G_rows.append(ca.horzcat(gu / n, 0, -sigma_scale))
        h_rows.append(hh / n)
    Gq, hq = ca.vertcat(*G_rows), ca.vertcat(*h_rows)
    H = A.T @ A
    sc = ca.trace(H)
    Pq = ca.SX.zeros(4, 4)
    Pq[0:2, 0:2] = 2 * H / sc
    cq = ca.vertcat(2 * A.T @ a_c / sc, c_rho * rho_scale / sc, c_sigma * sigma_scale / sc)
    chk = ca.sum1(ca.sum2(Pq)) + ca.sum1(cq) + ca.sum1(ca.sum2(Gq)) + ca.sum1(hq) + V
    fn = ca.Function(
        "clf_qp_loop", [x, L.symbol],
        [Pq, cq, Gq, hq, chk, eta, tau, V, a, A, w0, W, c_d, r_d, est],
        ["x", "p"],
        ["P", "c", "G", "h", "check", "eta", "tau", "V", "a", "A", "w0", "W", "c_d", "r_d",
         "estimator"],
        {"cse": True})
    return L, fn


def clf_qp_function(hip: HipProgress, x: ca.SX, reduced: Sequence[ca.SX], degree: int,
                    nominal_degree: int, bound_degree: int) -> tuple[Layout, ca.Function]:
    """The paper's robust CLF-QP in u-space (``clf_qp``, module docstring) at state x: its
    parameter layout and function; ``reduced`` = (f_p, g_m, g_s) at x."""
    f_p, g_m, g_s = reduced
    L = Layout()
    alpha = L.add("alpha_pk", (1, degree + 1))
    v_hip, p_min, p_max = L.add("v_hip"), L.add("p_min"), L.add("p_max")
    P_eps = L.add("P_eps", (3, 3))
    g_over_eps = L.add("gamma_over_eps")
    c_rho = L.add("c_rho")
    nom = L.add("nominal", (3, nominal_degree + 1))
    lo_c = L.add("lower", (3, bound_degree + 1))
    hi_c = L.add("upper", (3, bound_degree + 1))
    tau_lo, tau_hi = L.add("tau_lo"), L.add("tau_hi")

    o = stance_outputs(hip, x, alpha, v_hip, p_min, p_max)
    tau = o.tau
    eta = ca.vertcat(o.y1, o.y2, o.dy2)
    Jo = ca.jacobian(ca.vertcat(o.y1, o.dy2), x)
    Lf, Am, As = Jo @ f_p, Jo @ g_m, Jo @ g_s
    F, G = ca.DM(F_OUT), ca.DM(G_OUT)
    V = eta.T @ P_eps @ eta
    LFV = eta.T @ (P_eps @ F + F.T @ P_eps) @ eta
    LGV = 2 * eta.T @ P_eps @ G  # type: ignore[operator]  # 1 x 2; casadi's stubs: SX.T
    s = ca.fmin(ca.fmax((tau - tau_lo) / (tau_hi - tau_lo), 0), 1)
    Fstar = bezier.evaluate(nom, s)
    lo, hi = bezier.evaluate(lo_c, s), bezier.evaluate(hi_c, s)
    c_box = Fstar + 0.5 * (lo + hi)
    r_box = 0.5 * ca.fmax(hi - lo, 0)
    g_u = LGV @ Am  # 1 x 2
    a_F = As.T @ LGV.T  # 3
    h = -g_over_eps * V - LFV - LGV @ Lf - a_F.T @ c_box - ca.fabs(a_F).T @ r_box
    H = Am.T @ Am
    b0 = Lf + As @ Fstar
    b = Am.T @ b0
    sc = ca.trace(H)
    Pu = ca.SX.zeros(3, 3)
    Pu[0:2, 0:2] = 2 * H / sc
    cu = ca.vertcat(2 * b / sc, c_rho / sc)
    row_u = ca.horzcat(g_u, -g_over_eps)
    n_u = ca.norm_2(row_u)
    Gu, hu = row_u / n_u, h / n_u
    # one number that is non-finite iff any QP datum is (NaN and inf propagate)
    chk = ca.sum1(ca.sum2(Pu)) + ca.sum1(cu) + ca.sum2(Gu) + hu + V
    return L, ca.Function(
        "clf_qp", [x, L.symbol],
        [Pu, cu, Gu, hu, chk, eta, tau, V, LFV, LGV, Lf, Am, As, Fstar, c_box, r_box],
        ["x", "p"],
        ["Pu", "cu", "Gu", "hu", "check", "eta", "tau", "V", "LFV", "LGV", "Lf", "Am", "As",
         "Fstar", "c", "r"])


def stance_ref_function(hip: HipProgress, degree: int) -> tuple[Layout, ca.Function]:
    """The nominal stance trajectory of (th_pk, th_pa) at a phase and phase rate
    (``stance_ref``)."""
    R = Layout()
    alpha_r = R.add("alpha_pk", (1, degree + 1))
    rp_min, rp_max = R.add("p_min"), R.add("p_max")
    tau_s, rate = ca.SX.sym("tau"), ca.SX.sym("rate")
    Bk, dBk, ddBk = bezier.evaluate_continued(alpha_r, tau_s)
    qd_ = ca.vertcat(Bk, hip.ankle(delta_p_at(tau_s, rp_min, rp_max), Bk))
    dqd_ = rate * ca.vertcat(dBk, hip.ankle(step_length(rp_min, rp_max), dBk))
    ddqd_ = rate**2 * ca.vertcat(ddBk, -hip.c_knee * ddBk / hip.c_ankle)
    return R, ca.Function("stance_ref", [tau_s, rate, R.symbol], [qd_, dqd_, ddqd_],
                          ["tau", "rate", "p"], ["q_d", "qd_d", "qdd_d"])


def swing_ref_function(sub: ProsthesisSubsystem, x: ca.SX, degree: int, pitch_degree: int
                       ) -> tuple[Layout, ca.Function]:
    """The swing target with the landing offset and its gravity torque (``swing_ref``)."""
    th = x[0:2]
    S = Layout()
    alpha_s = S.add("alpha", (2, degree + 1))
    pitch_c = S.add("pitch", (1, pitch_degree + 1))
    reach, s_land = S.add("landing_reach"), S.add("landing_start")
    flat_span = S.add("landing_flatten")
    s_raw, rate_raw = ca.SX.sym("s_raw"), ca.SX.sym("rate_raw")
    s_c = ca.fmin(ca.fmax(s_raw, 0), 1)  # the Bezier rows hold their end values
    pitch = bezier.evaluate(pitch_c, s_c)
    Bs = bezier.evaluate(alpha_s, s_c)
    # landing, about the Bezier posture with the socket at its nominal pitch: the knee
    # turns the shank toward the vertical under the knee (the lowest the sole gets at a
    # fixed foot pitch) by the fraction w of its angle psi, and the ankle keeps the foot
    # flat in the world; both are exact (psi and the foot pitch are linear in the joint
    # angles, slopes +-1)
    qj, th_s = ca.SX.sym("qj", 2), ca.SX.sym("th_s")
    q5 = ca.vertcat(0, 0, th_s, qj)
    knee, ankle = (frame_pose(sub.tree, q5, f) for f in ("p_knee", "p_ankle"))
    psi = ca.atan2(ankle[0] - knee[0], knee[1] - ankle[1])  # shank from vertical
    foot = frame_pose(sub.tree, q5, "p_sole")[2]
    geo = ca.Function("landing_geometry", [qj, th_s],
                      [psi, ca.jacobian(psi, qj)[0], foot])
    psi0, dpsi_dk, pitch0 = geo(Bs, pitch)
    w = ca.fmin(ca.fmax(reach * (s_raw - s_land) / (1 - s_land), 0), 1)
    w_flat = ca.fmin(ca.fmax((s_raw - s_land) / flat_span, 0), 1)
    dk = -w * psi0 / dpsi_dk
    q_sw = Bs + ca.vertcat(dk, -dk - pitch0 * w_flat)
    qd_sw = ca.jacobian(q_sw, s_raw) * rate_raw
    qdd_sw = ca.jacobian(qd_sw, s_raw) * rate_raw
    _, H_free = mass_matrix_and_bias(sub.tree, sub.q, sub.qd)
    grav_free = ca.substitute(H_free, sub.qd, ca.SX.zeros(sub.nq))
    q_hang = ca.vertcat(0, 0, pitch, th)
    g_sw = ca.substitute(grav_free, sub.q, q_hang)[3:5]
    return S, ca.Function("swing_ref", [x, s_raw, rate_raw, S.symbol],
                          [q_sw, qd_sw, qdd_sw, g_sw, s_c],
                          ["x", "s_raw", "rate_raw", "p"],
                          ["q_d", "qd_d", "qdd_d", "gravity", "tau"])


def phase_pd_function(hip: HipProgress, x: ca.SX, degree: int, feedforward_degree: int
                      ) -> tuple[Layout, ca.Function]:
    """The phase-PD reference's feedforward and joint-side feedback (``phase_pd``)."""
    Q = Layout()
    alpha_q = Q.add("alpha_pk", (1, degree + 1))
    v_hip_q, p_min_q, p_max_q = Q.add("v_hip"), Q.add("p_min"), Q.add("p_max")
    ff = Q.add("feedforward", (2, feedforward_degree + 1))
    kp_q, kd_q, kv_q = Q.add("kp"), Q.add("kd"), Q.add("k_vhip")
    oq = stance_outputs(hip, x, alpha_q, v_hip_q, p_min_q, p_max_q)
    u_ff = bezier.evaluate(ff, ca.fmin(ca.fmax(oq.tau, 0), 1))
    fb = ca.vertcat(-kp_q * oq.y2 - kd_q * oq.dy2, kv_q * oq.y1)
    return Q, ca.Function("phase_pd", [x, Q.symbol],
                          [u_ff, fb, oq.tau, ca.vertcat(oq.y1, oq.y2, oq.dy2)],
                          ["x", "p"], ["u_ff", "fb_joint", "tau", "eta"])


def spong_law(sub: ProsthesisSubsystem, x: ca.SX, q_d: ca.SX, qd_d: ca.SX, qdd_d: ca.SX,
              Pl: Layout) -> tuple[ca.SX, ca.SX, ca.SX, ca.SX, list[str]]:
    """Spong's robust passivity-based law (module docstring) about the joint reference
    (``q_d``, ``qd_d``, ``qdd_d``; rad, rad/s, rad/s^2) on the flat-foot stance prosthesis,
    its gains and parameters added to ``Pl``: the joint torque, e, r, Y theta0 and the links
    whose standard parameters it adapts."""
    th, dth = x[0:2], x[2:4]
    lam, kgain = Pl.add("lam", (2,)), Pl.add("k", (2,))
    rho_th, bl = Pl.add("rho_theta"), Pl.add("boundary")
    links = [b.name for b in sub.tree.bodies if b.name != "p_foot"]
    theta0 = Pl.add("theta0", (4 * len(links) + len(drives(sub.tree)),))
    e, ed = th - q_d, dth - qd_d
    vv = qd_d - lam * e
    aa = qdd_d - lam * ed
    rr = ed + lam * e
    Y, _ = regressor(sub, x, aa, vv)
    # the robust term covers the links' parameters; the drives' armature (the last columns,
    # joint accelerations of up to 200 rad/s^2 in a stance) is the motors' datasheet's: with
    # it, rho = 0.2 kg m^2 switched 40 N m within the boundary layer and no gain walked
    n = 4 * len(links)
    YTr = Y[:, :n].T @ rr
    dtheta = ca.vertcat(-rho_th * YTr / ca.fmax(ca.norm_2(YTr), bl),
                        ca.SX.zeros(Y.shape[1] - n))
    return Y @ (theta0 + dtheta) - kgain * rr, e, rr, Y @ theta0, links


def passive_function(sub: ProsthesisSubsystem, x: ca.SX, stance_ref: ca.Function,
                     degree: int) -> tuple[Layout, ca.Function, list[str]]:
    """Spong's robust passivity-based law on the stance reference (``passive``), and the
    links whose standard parameters it adapts."""
    Pl = Layout()
    alpha_p = Pl.add("alpha_pk", (1, degree + 1))
    pp_min, pp_max = Pl.add("p_min"), Pl.add("p_max")
    tau_s, rate = ca.SX.sym("tau"), ca.SX.sym("rate")
    q_d, qd_d, qdd_d = stance_ref(tau_s, rate, ca.vertcat(alpha_p.T, pp_min, pp_max))
    u_pass, e, rr, y_theta0, links = spong_law(sub, x, q_d, qd_d, qdd_d, Pl)
    return Pl, ca.Function("passive", [x, tau_s, rate, Pl.symbol],
                           [u_pass, e, rr, y_theta0],
                           ["x", "tau", "rate", "p"], ["u_joint", "e", "r", "Ytheta0"]), links


def passive_reference_function(sub: ProsthesisSubsystem) -> tuple[Layout, ca.Function]:
    """Spong's law about a joint reference given as an input (``passive_ref(x, ref, p)``,
    ref = (q_d, qd_d, qdd_d), joint torque out): the multi-contact graph's ``passive``,
    whose reference is a table of the gait
    (:class:`prosthesis_controller.passive.ContactPassive`)."""
    x, ref = ca.SX.sym("x", 4), ca.SX.sym("ref", 6)
    Pl = Layout()
    u_pass, *_ = spong_law(sub, x, ref[0:2], ref[2:4], ref[4:6], Pl)
    return Pl, ca.Function("passive_ref", [x, ref, Pl.symbol], [u_pass],
                           ["x", "ref", "p"], ["u_joint"])


def reduced_model_functions(sub: ProsthesisSubsystem, x: ca.SX, reduced: Sequence[ca.SX]
                            ) -> list[ca.Function]:
    """The reduced model's pieces for tests and simulation: ``lagrangian``, ``regressor``,
    ``reduced`` (f_p, g_m, g_s)."""
    xs, M, g, C = reduced_lagrangian(sub)
    lag = ca.Function("lagrangian", [xs], [M, g, C @ xs[2:4]], ["x"], ["M", "g", "Cqd"])
    a_sym, v_sym = ca.SX.sym("a", 2), ca.SX.sym("v", 2)
    Y2, _ = regressor(sub, x, a_sym, v_sym)
    reg = ca.Function("regressor", [x, a_sym, v_sym], [Y2], ["x", "a", "v"], ["Y"])
    red = ca.Function("reduced", [x], list(reduced), ["x"], ["f_p", "g_m", "g_s"])
    return [lag, reg, red]


class ControllerTerms:
    """The compiled controller functions of one subsystem and Bezier degrees.

    ``gait_degree``: degree of the gait's alpha; ``nominal_degree`` / ``bound_degree``: of
    the tube's nominal and bound curves; ``pitch_degree``: of the swing socket-pitch fit;
    ``feedforward_degree``: of the phase-PD's nominal stance torque.
    """

    def __init__(self, sub: ProsthesisSubsystem, gait_degree: int, nominal_degree: int,
                 bound_degree: int, pitch_degree: int = 5,
                 backend: CompileBackend | str = CompileBackend.AUTO,
                 feedforward_degree: int = 9, margin_degree: int = 0) -> None:
        self.sub = sub
        hip = HipProgress.of(sub.full, Domain.PS)
        self.hip = hip
        m = gait_degree
        x = ca.SX.sym("x", 4)
        f_p, g_m, g_s = sub.functions["reduced"](x)
        reduced = (f_p, g_m, g_s)
        self.clf_layout, clf = clf_qp_function(hip, x, reduced, m, nominal_degree,
                                               bound_degree)
        self.clf_loop_layout, clf_loop = clf_qp_loop_function(sub, m, margin_degree)
        self.stance_layout, sref = stance_ref_function(hip, m)
        self.swing_layout, swref = swing_ref_function(sub, x, m, pitch_degree)
        self.phase_pd_layout, phase_pd = phase_pd_function(hip, x, m, feedforward_degree)
        self.passive_layout, passive, links = passive_function(sub, x, sref, m)
        self.passive_links = links
        fns = [clf, clf_loop, sref, swref, phase_pd, passive,
               *reduced_model_functions(sub, x, reduced)]
        name = (f"{sub.name}_ctrl_m{m}_k{nominal_degree}_l{bound_degree}_p{pitch_degree}"
                f"_f{feedforward_degree}_d{margin_degree}")
        self.functions = {f.name(): f for f in fns}
        self.numeric = FunctionSet(fns, name, backend)
        self.theta0 = standard_parameters(sub.tree, links)
