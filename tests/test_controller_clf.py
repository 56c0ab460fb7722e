"""Robust CLF-QP: the RES-CLF, the model terms (AD against finite differences and the
Lagrangian form), and the property of paper eq. robust_CLF_QP: whenever the exact QP is
solved, the CLF condition holds for EVERY socket force in the tube's box (checked at its 8
vertices); the relaxed QP with rho_max = 0 and no rate or torque bounds is the exact one."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from hp_model.domains import Domain
from prosthesis_controller import ClfConfig, ControllerConfig, ControllerContext, make_controller
from prosthesis_controller.clf import res_clf
from prosthesis_controller.interface import QpOutcome
from tests.controller_support import clf_terms, stance_meas, tube_about_nominal

# the tube suggested for tests: (F_x, F_z, M_y) half-widths in N, N, N m
HALF = (40.0, 60.0, 8.0)
VERTICES = np.array(list(itertools.product((-1.0, 1.0), repeat=3)))

# random stance states given by their phase: tau in [-0.05, 1.05], the knee within 0.15 rad
# of its nominal B_pk(tau), the ankle from the phase, velocities within 3 rad/s of zero
draws = st.tuples(st.floats(-0.05, 1.05), st.floats(-0.15, 0.15),
                  st.floats(-3.0, 3.0), st.floats(-3.0, 3.0))


def state_at(ctx, d) -> np.ndarray:
    tau, dk, vk, va = d
    ps = ctx.gait.params[Domain.PS]
    from hp_model import bezier
    from hp_model.domains import PROSTHESIS

    qk = float(bezier.evaluate(ps.alpha[Domain.PS.y2_row(PROSTHESIS[0])][None, :],
                               float(np.clip(tau, 0, 1)))[0]) + dk
    qa = ctx.terms.hip.ankle(ps.delta_p_at(tau), qk)
    return np.array([qk, qa, vk, va])


@pytest.fixture(scope="module")
def ctx(model, subsystem, template_gait):
    return ControllerContext(template_gait, tube_about_nominal(template_gait, HALF), model,
                             subsystem=subsystem)


@pytest.fixture(scope="module")
def ctx_exact_bounded(model, subsystem, template_gait):
    cfg = ControllerConfig(clf=ClfConfig(exact_limits_in_qp=True))
    return ControllerContext(template_gait, tube_about_nominal(template_gait, HALF), model,
                             cfg, subsystem=subsystem)


@pytest.fixture(scope="module")
def ctx_unbounded_relaxed(model, subsystem, template_gait):
    cfg = ControllerConfig(clf=ClfConfig(rho_max=0.0, delta_u=float("inf"),
                                         limits_in_qp=False))
    return ControllerContext(template_gait, tube_about_nominal(template_gait, HALF), model,
                             cfg, subsystem=subsystem)


def test_care_solution_and_constants_match_the_reference():
    """Q = I, R = I: P = [[1,0,0],[0,sqrt3,1],[0,1,sqrt3]], c3 = 0.366 (REFERENCE Sec. 2)."""
    r = res_clf(np.eye(3), np.eye(2), 0.1)
    s3 = np.sqrt(3.0)
    np.testing.assert_allclose(r.P, [[1, 0, 0], [0, s3, 1], [0, 1, s3]], atol=1e-12)
    assert r.c3 == pytest.approx(1.0 / (s3 + 1.0), rel=1e-12)  # lmax(P) = sqrt3 + 1
    np.testing.assert_allclose(r.P_eps, np.diag([1, 10, 1]) @ r.P @ np.diag([1, 10, 1]))


def test_lqr_law_meets_the_res_clf_rate():
    """With eps mu = -R^-1 G^T P I_eps eta, dV_eps/dt <= -(c3/eps) V_eps for every eta."""
    from prosthesis_controller.terms import F_OUT, G_OUT

    eps = 0.05
    r = res_clf(np.eye(3), np.eye(2), eps)
    I_eps = np.diag([1.0, 1.0 / eps, 1.0])
    rng = np.random.default_rng(3)
    for eta in rng.normal(size=(200, 3)):
        mu = -(G_OUT.T @ r.P @ I_eps @ eta) / eps
        dV = 2 * eta @ r.P_eps @ (F_OUT @ eta + G_OUT @ mu)
        assert dV <= -(r.c3 / eps) * (eta @ r.P_eps @ eta) * (1 - 1e-12)


def test_gamma_above_c3_is_refused(model, subsystem, template_gait):
    cfg = ControllerConfig(clf=ClfConfig(gamma=0.5))
    with pytest.raises(ValueError, match="c3"):
        ControllerContext(template_gait, tube_about_nominal(template_gait, HALF), model, cfg,
                          subsystem=subsystem)


def test_lie_derivatives_match_finite_differences(ctx):
    """LFV + LGV nu(u, F) (AD, generated C) = dV/dt along the reduced dynamics (central
    differences, step 1e-6 s: error O(h^2) ~ 1e-9 relative)."""
    red = ctx.terms.numeric["reduced"]
    rng = np.random.default_rng(5)
    for _ in range(20):
        x = np.r_[rng.uniform(0.0, 0.4), rng.uniform(-0.3, 0.3), rng.normal(size=2)]
        u, F = rng.normal(size=2), np.array([-100.0, -500.0, 20.0]) + rng.normal(size=3) * 30
        T = clf_terms(ctx, x)
        fp, gm, gs = (a.copy() for a in red(x))
        xd = fp + gm @ u + gs @ F
        h = 1e-6
        fd = (clf_terms(ctx, x + h * xd)["V"] - clf_terms(ctx, x - h * xd)["V"]) / (2 * h)
        lie = T["LFV"] + T["LGV"] @ (T["Lf"] + T["Am"] @ u + T["As"] @ F)
        assert lie[0] == pytest.approx(fd[0], rel=1e-6, abs=1e-8)


def test_reduced_lagrangian_is_consistent_with_the_reduced_dynamics(ctx):
    """M^-1 Gamma = g_m, -M^-1 (C qd + g) = the drift, Y theta0 = M a + C v + g, and
    Mdot - 2C is skew (the passivity property Spong's law relies on)."""
    fs = ctx.terms.numeric
    gear = np.diag(ctx.gear)
    rng = np.random.default_rng(7)
    for _ in range(10):
        x = np.r_[rng.uniform(0.0, 0.5, 1), rng.uniform(-0.3, 0.3, 1), rng.normal(size=2)]
        fp, gm, _ = (a.copy() for a in fs["reduced"](x))
        M, g, Cqd = (a.copy() for a in fs["lagrangian"](x))
        # M ~ 0.1 kg m^2, g_m ~ 1e3: relative agreement to the Cholesky round-off
        np.testing.assert_allclose(np.linalg.solve(M, gear), gm[2:], rtol=1e-8, atol=1e-6)
        np.testing.assert_allclose(-np.linalg.solve(M, Cqd + g), fp[2:], rtol=1e-8, atol=1e-6)
        a, v = rng.normal(size=2), x[2:]
        Y = fs["regressor"](x, a, v)[0].copy()
        np.testing.assert_allclose(Y @ ctx.terms.theta0, M @ a + Cqd + g, rtol=1e-10,
                                   atol=1e-10)
        # skew symmetry of Mdot - 2C along qd: w^T (Mdot - 2C) w = 0 for w = qd
        h = 1e-6
        Mdot = (fs["lagrangian"](x + h * np.r_[x[2:], 0, 0])[0].copy()
                - fs["lagrangian"](x - h * np.r_[x[2:], 0, 0])[0].copy()) / (2 * h)
        qd = x[2:]
        assert qd @ Mdot @ qd - 2 * qd @ Cqd == pytest.approx(0.0, abs=1e-6)


def _vertex_margin(ctx, x, u):
    """max over the 8 box vertices of dV/dt + (gamma/eps) V (must be <= 0), the
    worst-case row's value, and the row norm of the normalised QP (scale of the residual)."""
    T = clf_terms(ctx, x)
    T["LGV"] = T["LGV"].ravel()
    c, r = T["c"], T["r"]
    goe = ctx.config.clf.gamma / ctx.config.clf.eps
    vals = []
    for s in VERTICES:
        nu = T["Lf"] + T["Am"] @ u + T["As"] @ (c + s * r)
        vals.append(float(T["LFV"][0] + T["LGV"] @ nu + goe * T["V"][0]))
    a = T["As"].T @ T["LGV"]
    row = float(T["LFV"][0] + T["LGV"] @ (T["Lf"] + T["Am"] @ u) + a @ c + np.abs(a) @ r
                + goe * T["V"][0])
    # norm of the solver's CLF row (whitened variables w = Am u / |Am|_F): the factor from
    # its normalised residual to dV/dt units
    nrm = float(np.hypot(np.linalg.norm(T["Am"]) * np.linalg.norm(T["LGV"]), goe))
    return max(vals), row, nrm


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(d=draws)
def test_exact_qp_satisfies_the_clf_condition_at_every_box_vertex(ctx, ctx_exact_bounded, d):
    x = state_at(ctx, d)
    for c in (ctx, ctx_exact_bounded):
        ctl = make_controller("clfqp-paper-exact", None, None, None, context=c)
        ctl.reset()
        out = ctl.tick(stance_meas(0.0, x))
        if out.diagnostics.qp_status != QpOutcome.SOLVED:
            assert c is ctx_exact_bounded  # only torque bounds can make it infeasible
            assert out.diagnostics.mode == "fallback"
            continue
        u = ctl.qp_solution[:2].copy()
        worst, row, nrm = _vertex_margin(c, x, u)
        # the normalised row is solved to eps = 1e-10; allow 1000x for piqp's scaling
        tol = 1e-7 * nrm
        assert worst <= tol
        # one worst-case row = the max over the vertices (same feasible set, exactly)
        assert row == pytest.approx(worst, rel=1e-9, abs=1e-9 * nrm)


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(d=draws)
def test_relaxed_without_relaxation_or_bounds_is_the_exact_qp(ctx, ctx_unbounded_relaxed, d):
    x = state_at(ctx, d)
    exact = make_controller("clfqp-paper-exact", None, None, None, context=ctx)
    relaxed = make_controller("clfqp-paper", None, None, None, context=ctx_unbounded_relaxed)
    exact.reset()
    relaxed.reset()
    oe, orl = exact.tick(stance_meas(0.0, x)), relaxed.tick(stance_meas(0.0, x))
    assert oe.diagnostics.qp_status == orl.diagnostics.qp_status == QpOutcome.SOLVED
    ue, ur = exact.qp_solution[:2], relaxed.qp_solution[:2]
    # both are interior-point solutions to 1e-9 of the normalised problem; torques ~ 1 N m
    np.testing.assert_allclose(ur, ue, rtol=1e-6, atol=1e-6)
    np.testing.assert_allclose(orl.torque, oe.torque, rtol=1e-6, atol=1e-6)
    assert abs(relaxed.qp_solution[2]) <= 1e-9


def test_the_law_sees_the_tube_widened_by_its_allowance(ctx, model, subsystem, template_gait):
    """The box in the CLF row is the tube in use: certified bounds +/- the allowance."""
    import dataclasses

    allow = np.array([5.0, 7.0, 1.5])
    wide = dataclasses.replace(ctx.tube, allowance=allow)
    wctx = ControllerContext(template_gait, wide, model, subsystem=subsystem)
    for tau in (0.2, 0.5, 0.8):
        x = state_at(ctx, (tau, 0.05, 0.5, -0.5))
        T, W = clf_terms(ctx, x), clf_terms(wctx, x)
        np.testing.assert_allclose(W["c"].ravel(), T["c"].ravel(), atol=1e-9)
        np.testing.assert_allclose(W["r"].ravel(), T["r"].ravel() + allow, atol=1e-9)
        c, r = wide.box(float(W["tau"].ravel()[0]))
        np.testing.assert_allclose(W["r"].ravel(), r, atol=1e-9)
        np.testing.assert_allclose(W["c"].ravel(), c, atol=1e-9)
