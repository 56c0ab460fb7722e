"""PHZD gait optimization by direct collocation (paper Sec. IV-A; what FROST does).

The cycle ps -> pns -> ps with impacts, each domain discretised by Hermite-Simpson
collocation (separated form: midpoints carry their own variables).  At every collocation
point the model's equations hold in inverse-dynamics form,

    D qdd + H = B u + J^T lam,     J qdd + Jdot qd = 0,

and the closed-loop output dynamics of the feedback-linearizing controller hold,

    dy1 + eps y1 = 0,    ddy2 + kd dy2 + kp y2 = 0,

with y2 = 0 and dy2 = 0 at the first point of each domain (partial hybrid zero dynamics:
the relative-degree-2 outputs are impact invariant, y1 is not).  The trajectory is thus the
one the controller produces; the decision variables are the gait parameters (alpha_v,
v_hip, p_min, p_max), offsets delta_alpha and the states.  Cost as the paper: the
weighted integral of squared Bezier differences as a quadratic form (``bezier.gram``) plus
the step-length term; plus, not in the paper, ``w_offset`` times the squared offsets (see
:class:`PHZDOptions`; 0 gives the paper's cost exactly).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import casadi as ca
import numpy as np

from characterization.gait.nlp import NLP
from hp_model import bezier
from hp_model.blas_threads import single_threaded_blas
from hp_model.domains import N_Y2, PAPER_DOMAINS, Domain
from hp_model.human_prosthesis import HumanProsthesisModel
from hp_model.outputs import (
    GaitParams,
    VirtualConstraints,
    plain,
    step_length,
    unpack_symbolic,
)


class GaitOptimizationError(RuntimeError):
    """IPOPT did not converge; the message carries its status."""


class GaitVerificationError(RuntimeError):
    """The optimized gait does not walk (falls, or its return map is not contracting); the
    message names the failed check with its numbers."""


@dataclass(frozen=True)
class PHZDOptions:
    """Settings of the gait optimization (SI units)."""

    nodes: int = 21  # collocation nodes per domain (plus the midpoints)
    degree: int = 5  # Bezier degree of y2
    eps: float = 10.0  # y1 gain (1/s)
    kp: float = 100.0  # y2 gains in the collocation constraints (the orbit does not depend
    kd: float = 20.0  # on them: y2 = 0 on it)
    track_kp: float = 1600.0  # y2 gains of the human-side feedback linearization stored
    track_kd: float = 80.0  # with the gait (w = 40 rad/s; at w = 10 the return map of a
    #  test gait had an eigenvalue of 9.3, at w = 40 all were below 0.31)
    mu: float = 0.6  # friction coefficient
    min_normal_force: float = 20.0  # N
    clearance: float = 0.02  # m, swing sole height at mid-step
    touchdown_velocity: float = 0.05  # m/s, least downward swing-sole speed at touchdown (a
    #  grazing touchdown makes the impact time, and so the gait, fragile)
    touchdown_slip: float = np.inf  # m/s, largest forward/backward swing-sole speed at
    #  touchdown (off by default: tight values made IPOPT fail on the synthetic subject)
    touchdown_pitch_rate: float = np.inf  # rad/s, largest swing-foot pitch rate at touchdown
    w_y1: float = 10.0
    w_y2: tuple[float, ...] = (1.0, 1.0, 1.0, 1.0, 1.0)
    w_step: float = 100.0
    w_offset: float = 0.1  # weight of sum(delta_alpha^2) per domain: not in the paper's J_v.
    #  Without it the offsets are not identified (a valley: trunk pitch against both hip
    #  angles); on the model-generated subject (true offsets 0) IPOPT then drifted to
    #  offsets of 8.6 deg and a gait 8.8 deg from the truth, at 0.2 deg from the data
    duration_bounds: tuple[float, float] = (0.2, 1.5)  # s per domain
    min_step: float = 0.0  # m, least hip progress p_max - p_min per domain (0: unbounded)
    min_hip_velocity: float = 0.0  # m/s, least v_hip (0: unbounded).  Off by default: the
    #  bounds change IPOPT's path on every gait; ``fit_gait`` solves again with them
    #  (STEP_FLOOR) when IPOPT collapses a step (p_max = p_min: tau = 0/0, no gait)
    offset_bound: float = 0.15  # rad, |delta_alpha| (marker-placement offsets, not a free fit)
    expand: bool = False  # expand the NLP to SX: 15x faster derivatives, but on the
    #  synthetic subject IPOPT then ended in a far worse local optimum (RMS 15-47 deg)
    max_iter: int = 1000
    tol: float = 1e-6
    mu_strategy: str = "monotone"  # IPOPT's barrier update: "adaptive" diverged (restoration
    #  failure) on the kinematic template subject once the offsets were regularized
    print_level: int = 0


@dataclass(frozen=True)
class DataTargets:
    """What the regression of the mocap data gives per domain: alpha_mc (5, m+1), the mean
    hip velocity, and the mean phase bounds."""

    alpha: dict[Domain, np.ndarray]
    v_hip: dict[Domain, float]
    p_min: dict[Domain, float]
    p_max: dict[Domain, float]


@dataclass
class PHZDResult:
    params: dict[Domain, GaitParams]
    offsets: dict[Domain, np.ndarray]
    durations: dict[Domain, float]
    trajectory: dict[Domain, dict[str, np.ndarray]]
    status: str
    success: bool
    iterations: int
    solve_seconds: float
    cost: float
    stats: dict = field(default_factory=dict)


def _point_functions(model: HumanProsthesisModel, vc: VirtualConstraints, opt: PHZDOptions):
    """SX functions of one collocation point: equality residuals and inequalities."""
    q, qd = model.q, model.qd
    qdd = ca.SX.sym("qdd", model.nq)
    u = ca.SX.sym("u", model.nu)
    lam = ca.SX.sym("lam", 6)
    theta = ca.SX.sym("theta", vc.n_params)
    h = model.h[vc.domain]
    J = ca.jacobian(h, q)
    Jdqd = ca.jtimes(J @ qd, q, qd)
    dyn = model.D @ qdd + model.H - ca.DM(model.B) @ u - J.T @ lam
    hol = J @ qdd + Jdqd
    o = vc.output_exprs(q, qd, theta, qdd, plain)
    y1, dy1, y2, dy2, ddy2 = o.y1, o.dy1, o.y2, o.dy2, o.ddy2
    eq = ca.vertcat(dyn, hol, dy1 + opt.eps * y1, ddy2 + opt.kd * dy2 + opt.kp * y2)
    # ground wrench (F_x, F_z, M_y) at the stance sole point: friction cone, positive
    # normal force, centre of pressure inside the foot (d = -M_y / F_z in [-heel, toe])
    roles = model.roles[vc.domain]
    frames = {f.name: f for f in model.tree.frames}
    heel = -frames[roles.stance_foot[0]].point[0]
    toe = frames[roles.stance_foot[1]].point[0]
    fx, fz, my = lam[0], lam[1], lam[2]
    z_heel = model.frame_expr(roles.swing_foot[0])[1]
    z_toe = model.frame_expr(roles.swing_foot[1])[1]
    ineq = ca.vertcat(opt.mu * fz - fx, opt.mu * fz + fx, fz - opt.min_normal_force,
                      toe * fz + my, heel * fz - my, z_heel, z_toe)
    args = [q, qd, qdd, u, lam, theta]
    names = ["q", "qd", "qdd", "u", "lam", "theta"]
    f_eq = ca.Function(f"colloc_eq_{vc.domain}", args, [eq], names, ["eq"])
    f_in = ca.Function(f"colloc_ineq_{vc.domain}", args, [ineq], names, ["ineq"])
    f_out = ca.Function(f"start_outputs_{vc.domain}", [q, qd, theta],
                        [ca.vertcat(y2, dy2), o.tau], ["q", "qd", "theta"], ["y2dy2", "tau"])
    return f_eq, f_in, f_out


def initial_guess(model: HumanProsthesisModel, vc: VirtualConstraints, p: GaitParams,
                  n_points: int) -> dict[str, np.ndarray]:
    """A trajectory on the zero-dynamics surface of the data's curves at constant hip
    velocity: postures from ``vc.posture``, derivatives by finite differences in tau,
    (u, lam) from the square system [B J^T] [u; lam] = D qdd + H."""
    taus = np.linspace(0.0, 1.0, n_points)
    Q = np.array([vc.posture(t, p) for t in taus]).T
    Q[0] -= Q[0, 0]
    tau_dot = p.nominal_rate
    dQ = np.gradient(Q, taus, axis=1) * tau_dot
    ddQ = np.gradient(dQ, taus, axis=1) * tau_dot
    terms = model.numeric()[f"terms_{vc.domain}"]
    U, L = np.zeros((model.nu, n_points)), np.zeros((6, n_points))
    for k in range(n_points):
        D, H, J, _ = terms(Q[:, k], dQ[:, k])
        sol, *_ = np.linalg.lstsq(np.hstack([model.B, J.T]), D @ ddQ[:, k] + H, rcond=None)
        U[:, k], L[:, k] = sol[: model.nu], sol[model.nu:]
    return {"q": Q, "qd": dQ, "qdd": ddQ, "u": U, "lam": L, "T": np.array(p.nominal_duration)}


def _domain_variables(nlp: NLP, model: HumanProsthesisModel, vc: VirtualConstraints,
                      p_mc: GaitParams, opt: PHZDOptions) -> dict[str, ca.MX]:
    """The decision variables of one domain (states, accelerations, torques u, wrenches
    lam at the 2 nodes - 1 points; duration T; gait parameters theta; offsets delta), with
    :func:`initial_guess` on the data's curves ``p_mc`` as their start."""
    d, P = vc.domain, 2 * opt.nodes - 1
    ulim = np.where(np.isfinite(model.torque_limits), model.torque_limits, 1e4)
    guess = initial_guess(model, vc, p_mc, P)
    return {
        "q": nlp.var(f"q_{d}", (model.nq, P), guess["q"]),
        "qd": nlp.var(f"qd_{d}", (model.nq, P), guess["qd"]),
        "qdd": nlp.var(f"qdd_{d}", (model.nq, P), guess["qdd"]),
        "u": nlp.var(f"u_{d}", (model.nu, P), guess["u"], -ulim[:, None], ulim[:, None]),
        "lam": nlp.var(f"lam_{d}", (6, P), guess["lam"]),
        "T": nlp.var(f"T_{d}", (1, 1), guess["T"], *opt.duration_bounds),
        "theta": nlp.var(f"theta_{d}", (vc.n_params, 1), p_mc.pack()),
        "delta": nlp.var(f"delta_{d}", (N_Y2, 1), 0.0, -opt.offset_bound, opt.offset_bound),
    }


def _collocation(nlp: NLP, X: dict[str, ca.MX], f_eq: ca.Function, f_in: ca.Function,
                 opt: PHZDOptions) -> None:
    """One domain's path constraints at every point (:func:`_point_functions`) and its
    Hermite-Simpson defects (separated form: nodes at even points, midpoints at odd)."""
    N, P = opt.nodes, 2 * opt.nodes - 1
    th = ca.repmat(X["theta"], 1, P)
    args = [X["q"], X["qd"], X["qdd"], X["u"], X["lam"], th]
    nlp.eq(f_eq.map(P)(*args))
    ineq = f_in.map(P)(*args)
    nlp.geq(ineq[:5, :])
    nlp.geq(ineq[5:, 1:-1])  # swing foot above ground between lift-off and touchdown
    h = X["T"] / (N - 1)
    q, qd, qdd = X["q"], X["qd"], X["qdd"]
    k0, kc, k1 = slice(0, P - 2, 2), slice(1, P - 1, 2), slice(2, P, 2)
    nlp.eq(q[:, kc] - (q[:, k0] + q[:, k1]) / 2 - h / 8 * (qd[:, k0] - qd[:, k1]))
    nlp.eq(qd[:, kc] - (qd[:, k0] + qd[:, k1]) / 2 - h / 8 * (qdd[:, k0] - qdd[:, k1]))
    nlp.eq(q[:, k1] - q[:, k0] - h / 6 * (qd[:, k0] + 4 * qd[:, kc] + qd[:, k1]))
    nlp.eq(qd[:, k1] - qd[:, k0] - h / 6 * (qdd[:, k0] + 4 * qdd[:, kc] + qdd[:, k1]))


def _boundaries(nlp: NLP, model: HumanProsthesisModel, d: Domain, X: dict[str, ca.MX],
                f_out: ca.Function, opt: PHZDOptions) -> None:
    """One domain's ends: the start on the PHZD surface (y2 = dy2 = 0) at tau = 0 with the
    stance foot flat on the ground, the end at tau = 1; the guard (swing sole on the ground,
    flat, moving down; optionally nearly still along the ground and in pitch) and the
    mid-step clearance; in ps the prosthesis sole at x = 0 at the start."""
    P = 2 * opt.nodes - 1
    q, qd = X["q"], X["qd"]
    y2s, tau0 = f_out(q[:, 0], qd[:, 0], X["theta"])
    nlp.eq(y2s)
    nlp.eq(tau0)
    _, tau1 = f_out(q[:, -1], qd[:, -1], X["theta"])
    nlp.eq(tau1 - 1.0)
    # the phase is defined only while the hip progresses: without these bounds IPOPT can
    # collapse the step (p_max = p_min, tau = 0/0) where no walking gait is feasible
    _, v_hip, p_min, p_max = unpack_symbolic(X["theta"], opt.degree)
    if opt.min_step > 0:
        nlp.geq(step_length(p_min, p_max), opt.min_step)
    if opt.min_hip_velocity > 0:
        nlp.geq(v_hip, opt.min_hip_velocity)
    h_d = ca.Function("h", [model.q], [model.h[d]])
    nlp.eq(h_d(q[:, 0])[1:])  # stance sole z = 0, pitch = 0; socket q_f = 0
    fe = model.frame_expr(model.roles[d].swing_frame)
    sw = ca.Function("sw", [model.q, model.qd],
                     [fe, ca.jtimes(fe[1], model.q, model.qd)])
    pose_e, vz_e = sw(q[:, -1], qd[:, -1])
    nlp.eq(pose_e[1:])
    nlp.within(vz_e, -np.inf, -opt.touchdown_velocity)
    for i, bound in ((0, opt.touchdown_slip), (2, opt.touchdown_pitch_rate)):
        if np.isfinite(bound):
            vi = ca.Function("v", [model.q, model.qd], [ca.jtimes(fe[i], model.q, model.qd)])
            nlp.within(vi(q[:, -1], qd[:, -1]), -bound, bound)
    pose_m, _ = sw(q[:, P // 2], qd[:, P // 2])
    nlp.geq(pose_m[1], opt.clearance)
    if d == Domain.PS:
        nlp.eq(h_d(q[:, 0])[0])  # the cycle starts with the prosthesis sole at x = 0


def _add_domain_cost(cost: ca.MX, X: dict[str, ca.MX], targets: DataTargets, d: Domain,
                     opt: PHZDOptions) -> ca.MX:
    """``cost`` plus one domain's terms (paper): the integral of the squared Bezier
    differences from the data's curves (shifted by the offsets), the hip-velocity and the
    step-length terms; plus ``w_offset`` times the squared offsets."""
    G = bezier.gram(opt.degree)
    a_mc = np.asarray(targets.alpha[d])
    alpha, v_hip, p_min, p_max = unpack_symbolic(X["theta"], opt.degree)
    for k in range(N_Y2):
        e = alpha[k, :].T - a_mc[k, :] - X["delta"][k]
        cost += opt.w_y2[k] * (e.T @ G @ e)
    cost += opt.w_y1 * (v_hip - targets.v_hip[d]) ** 2
    cost += opt.w_offset * ca.sumsqr(X["delta"])
    cost += opt.w_step * (step_length(targets.p_min[d], targets.p_max[d])
                          - step_length(p_min, p_max)) ** 2
    return cost


def _impacts(nlp: NLP, model: HumanProsthesisModel, dec: dict[Domain, dict[str, ca.MX]]
             ) -> None:
    """The impacts ps -> pns and pns -> ps (impulse variables; periodic up to a forward
    translation)."""
    for d in PAPER_DOMAINS:
        nxt = model.roles[d].next
        qe, qde = dec[d]["q"][:, -1], dec[d]["qd"][:, -1]
        qd_plus = nlp.var(f"qdplus_{d}", (model.nq, 1), 0.0)
        F_I = nlp.var(f"impulse_{d}", (6, 1), 0.0)
        terms = model.function(f"terms_{nxt}")
        D, _, E, _ = terms(qe, qde)
        nlp.eq(D @ (qd_plus - qde) - E.T @ F_I)
        nlp.eq(E @ qd_plus)
        nlp.geq(F_I[1])  # the landing foot pushes on the ground, never pulls
        q0n = dec[nxt]["q"][:, 0]
        nlp.eq(dec[nxt]["qd"][:, 0] - qd_plus)
        if nxt == Domain.PNS:
            nlp.eq(q0n - qe)
        else:
            nlp.eq(q0n[1:] - qe[1:])  # x_B free: the ps start fixes the sole at x = 0


def _solve(nlp: NLP, cost: ca.MX, opt: PHZDOptions) -> tuple[dict, dict, float]:
    """IPOPT's solution, its statistics and the solve's wall time (s)."""
    problem = {"x": ca.vertcat(*nlp.w), "f": cost, "g": ca.vertcat(*nlp.g)}
    ipopt: dict[str, int | float | str] = {
        "max_iter": opt.max_iter, "tol": opt.tol, "print_level": opt.print_level,
        "linear_solver": "mumps", "mu_strategy": opt.mu_strategy, "sb": "yes"}
    solver = ca.nlpsol("phzd", "ipopt", problem, {"ipopt": ipopt, "print_time": False,
                                                  "expand": opt.expand})
    x0 = np.concatenate(nlp.w0)
    t0 = time.perf_counter()
    with single_threaded_blas():  # the same iterates whatever the thread settings
        sol = solver(x0=x0, lbx=np.concatenate(nlp.lbw), ubx=np.concatenate(nlp.ubw),
                     lbg=np.concatenate(nlp.lbg), ubg=np.concatenate(nlp.ubg))
    return sol, solver.stats(), time.perf_counter() - t0


def _result(nlp: NLP, dec: dict[Domain, dict[str, ca.MX]], sol: dict, stats: dict,
            elapsed: float, opt: PHZDOptions) -> PHZDResult:
    """The solution's gait parameters, offsets, durations and trajectories per domain."""
    P = 2 * opt.nodes - 1
    xs = np.array(sol["x"]).ravel()
    unpack = ca.Function("unpack", [ca.vertcat(*nlp.w)],
                         [dec[d][k] for d in PAPER_DOMAINS
                          for k in ("q", "qd", "qdd", "u", "lam", "T", "theta", "delta")])
    vals = [np.array(v) for v in unpack(xs)]
    params: dict[Domain, GaitParams] = {}
    offsets: dict[Domain, np.ndarray] = {}
    durations: dict[Domain, float] = {}
    traj: dict[Domain, dict[str, np.ndarray]] = {}
    for i, d in enumerate(PAPER_DOMAINS):
        q, qd, qdd, u, lam, T, theta, delta = vals[8 * i: 8 * i + 8]
        params[d] = GaitParams.unpack(theta.ravel(), opt.degree)
        offsets[d] = delta.ravel()
        durations[d] = float(T.item())
        traj[d] = {"t": np.linspace(0, float(T.item()), P), "q": q, "qd": qd, "qdd": qdd, "u": u,
                   "lam": lam}
    return PHZDResult(params=params, offsets=offsets, durations=durations, trajectory=traj,
                      status=stats["return_status"], success=bool(stats["success"]),
                      iterations=int(stats["iter_count"]), solve_seconds=elapsed,
                      cost=float(sol["f"]), stats={k: v for k, v in stats.items()
                                                   if isinstance(v, int | float | str)})


def optimize_gait(model: HumanProsthesisModel, targets: DataTargets,
                  opt: PHZDOptions | None = None) -> PHZDResult:
    """Solve the two-domain PHZD optimization with IPOPT (exact Hessian, MUMPS)."""
    opt = opt or PHZDOptions()
    nlp = NLP()
    dec: dict[Domain, dict[str, ca.MX]] = {}
    cost = ca.MX(0)
    for d in PAPER_DOMAINS:
        vc = VirtualConstraints(model, d, opt.degree)
        p_mc = GaitParams(np.asarray(targets.alpha[d]), targets.v_hip[d], targets.p_min[d],
                          targets.p_max[d])
        X = dec[d] = _domain_variables(nlp, model, vc, p_mc, opt)
        f_eq, f_in, f_out = _point_functions(model, vc, opt)
        _collocation(nlp, X, f_eq, f_in, opt)
        _boundaries(nlp, model, d, X, f_out, opt)
        cost = _add_domain_cost(cost, X, targets, d, opt)
    _impacts(nlp, model, dec)
    sol, stats, elapsed = _solve(nlp, cost, opt)
    return _result(nlp, dec, sol, stats, elapsed, opt)
