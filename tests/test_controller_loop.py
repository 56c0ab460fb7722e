"""The interaction-aware robust CLF-QP (``clfqp``, ``clfqp-exact``): its QP cross-checked
against a second solver, its rows meaning what they say, and the controller walking the full
human-prosthesis loop on the default subject's gait."""

from __future__ import annotations

import numpy as np
import pytest
import quadprog

from hp_model.force_tube import load_tube
from orchestrator.experiments.scenarios import NOMINAL, Scenario, run_scenario
from prosthesis_controller import ControllerContext, make_controller
from prosthesis_controller.interface import QpOutcome
from tests.controller_support import stance_meas

N_STATES = 600
# |nu|^2 is flat along A's weak direction (the torque Hessian's eigenvalues differ by 1e3-1e4):
# piqp at its tolerance (1e-8) and quadprog (exact, but for the curvature it needs on the
# slacks and the round-off the weak direction amplifies) stop at torques whose costs agree to
# 1e-12 yet lie up to ~2e-2 motor N m apart along it (measured; 1e-12 median).  What matters is
# checked tightly: feasibility and a cost as low as quadprog's; the torques within 3e-2 motor
# N m (1.5 N m at the knee joint, a direction that barely moves the outputs).
TOL_U = 3e-2


@pytest.fixture(scope="module")
def demo_ctx(model, subsystem, demo_gait):
    from tests.committed_gaits import ROOT

    tube = load_tube(ROOT / "tests/data/controller/tube_demo.json", demo_gait.hash())
    return ControllerContext(demo_gait, tube, model, subsystem=subsystem)


def _quadprog(P, c, G, h, xl, xu):
    """min 1/2 z^T P z + c^T z, G z <= h, xl <= z <= xu with quadprog (dual active set).
    The slack variables (rho, sigma scaled to [0, 1]) enter the cost linearly; quadprog needs
    P definite: a curvature of 1e-4 of the torques' on them moves the optimum by at most
    1e-4 z_slack^2 in cost, nothing where the slacks are zero (almost every instance)."""
    n = len(c)
    Pr = P + np.diag([0.0, 0.0, *([1e-4 * np.trace(P[:2, :2])] * (n - 2))])
    rows, rhs = [-g for g in G], [-v for v in h]
    for i in range(n):
        e = np.zeros(n)
        e[i] = 1.0
        if np.isfinite(xl[i]):
            rows.append(e)
            rhs.append(xl[i])
        if np.isfinite(xu[i]):
            rows.append(-e)
            rhs.append(-xu[i])
    try:
        return quadprog.solve_qp(Pr, -c, np.array(rows).T, np.array(rhs), 0)[0]
    except ValueError:
        return None


def _states(gait, model, n, rng):
    tr = gait.trajectory["ps"]
    i = [model.coord_names.index(c) for c in ("th_pk", "th_pa")]
    k = rng.integers(0, tr["q"].shape[1], n)
    x = np.r_[tr["q"][i][:, k], tr["qd"][i][:, k]].T
    return x + rng.normal(size=(n, 4)) * np.array([0.02, 0.02, 0.3, 0.3])


@pytest.mark.parametrize("name", ["clfqp", "clfqp-exact"])
def test_piqp_agrees_with_quadprog(demo_ctx, model, demo_gait, name):
    ctl = make_controller(name, None, None, None, context=demo_ctx)
    rng = np.random.default_rng(17 if name == "clfqp" else 18)
    lim = np.array(demo_ctx.limits)
    solved = 0
    for x in _states(demo_gait, model, N_STATES, rng):
        ctl.reset(rng.uniform(-lim, lim))
        out = ctl.tick(stance_meas(0.0, x))
        ref = _quadprog(*ctl.qp_data())
        if out.diagnostics.qp_status != QpOutcome.SOLVED:
            assert name == "clfqp-exact", out.diagnostics.qp_status  # relaxed: always solvable
            assert ref is None, "piqp failed on a QP quadprog solves"
            continue
        assert ref is not None
        P, c, G, h, xl, xu = ctl.qp_data()
        z = ctl.qp_solution
        # rows normalised (torque-equivalent units); piqp at 1e-8, the torques clipped to their
        # box after it: 1e-6 is far below anything physical
        assert np.all(G @ z <= h + 1e-6 * (1 + np.abs(h)))
        assert np.all(xl - 1e-7 <= z) and np.all(z <= xu + 1e-7)  # piqp at eps 1e-8
        # as low a cost as quadprog's (its point clipped to the bounds it misses by ~1e-9) up
        # to piqp's duality gap: by weak duality its cost is within the gap of the optimum,
        # quadprog's at or above it.  The slacks' linear costs (~30-350 per unit) make a row
        # left 1e-9 short of active worth ~1e-6 of cost; the gap says how much (up to 6e-6
        # measured).  1e-7 relative covers the clamp to the box and the two solvers' round-off.
        ref = np.clip(ref, xl, xu)
        cost, cost_ref = 0.5 * z @ P @ z + c @ z, 0.5 * ref @ P @ ref + c @ ref
        gap = ctl.qp_duality_gap
        assert cost <= cost_ref + gap + 1e-7 * (1 + abs(cost)), (cost, cost_ref, gap)
        np.testing.assert_allclose(z[:2], ref[:2], atol=TOL_U)
        solved += 1
    assert solved >= (0.9 if name == "clfqp" else 0.8) * N_STATES  # exact: infeasible ones


def test_rows_hold_at_the_solution(demo_ctx, model, demo_gait):
    """Where the QP needs no relaxation, its solution keeps the stance foot's predicted
    wrench in the friction cone (mu), above f_min and with the centre of pressure on the
    foot, and the CLF condition dV <= -(gamma/eps) V holds in the restricted model."""
    ctl = make_controller("clfqp", None, None, None, context=demo_ctx)
    ct = demo_ctx.config.contact
    c = demo_ctx.config.clf
    from prosthesis_controller.context import foot_extent

    toe, heel = (ct.cop_fraction * v for v in foot_extent(model))
    rng = np.random.default_rng(5)
    checked = 0
    for x in _states(demo_gait, model, 300, rng):
        ctl.reset()
        ctl.tick(stance_meas(0.0, x))
        z = ctl.qp_solution
        if z is None or z[3] > 1e-9:
            continue
        o = ctl.terms_out
        u = z[:2]
        fx, fz, my = o["w0"] + o["W"] @ u
        tol = 1e-6 * (1 + abs(fz))
        assert abs(fx) <= ct.mu * fz + tol and fz >= ct.f_min - tol
        assert -heel * fz - tol <= -my <= toe * fz + tol
        if z[2] <= 1e-12:
            eta = o["eta"]
            nu = o["a"] + o["A"] @ u  # (dy1, ddy2)
            P = demo_ctx.clf.P_eps
            deta = np.array([nu[0], eta[2], nu[1]])
            dV = 2 * eta @ P @ deta
            assert dV <= -(c.gamma / c.eps) * float(o["V"][0]) + 1e-6 * (1 + abs(dV))
        checked += 1
    assert checked > 100


def test_clfqp_walks_the_full_loop_on_the_default_subject(model, demo_ctx, demo_gait):
    """20 steps of the 12-DOF loop (the human tracking its gait, the prosthesis controlled
    from its own measurements at 1 kHz): no fall, knee RMS <= 0.003 rad (the issue), every
    torque within the device limits, every stance tick solved."""
    r = run_scenario(model, demo_gait, demo_ctx.tube, Scenario("clfqp", NOMINAL, 20),
                     context=demo_ctx)
    assert r.success, r.reason
    assert r.knee_rms("ps") <= 0.003, r.knee_rms("ps")
    assert np.all(np.abs(r.torque) <= np.array(demo_ctx.limits) + 1e-12)
    assert r.fallback_count == 0
    assert set(r.mode) == {"stance", "swing"}


def test_the_compensated_drift_shifts_the_clf_row_and_the_cost_by_d(demo_ctx, demo_gait,
                                                                     model):
    """``uncertainty.compensate``: the generated QP with the model-error estimate d_c in its
    parameters is the QP of the drift a + d_c: the CLF row's right side moves by
    -LGV d_c (LGV = the row's torque part times A^-1, both normalised alike) and the
    cost's torque gradient by 2 A^T d_c / trace(A^T A)."""
    f = demo_ctx.terms.numeric["clf_qp_loop"]
    k = demo_ctx.terms.clf_loop_layout.offset("d_hat")
    d = np.array([0.3, -40.0])  # (dy1 m/s^2, d2y2 rad/s^2)
    for x in _states(demo_gait, model, 20, np.random.default_rng(9)):
        out = []
        for dh in (np.zeros(2), d):
            f.inputs[0][:] = x
            f.inputs[1][:] = demo_ctx.clf_loop_params
            f.inputs[1][k:k + 2] = dh
            f.call_inplace()
            o = dict(zip(f.function.name_out(), f.outputs, strict=True))
            out.append({n: np.array(o[n], copy=True) for n in ("G", "h", "c", "A")})
        (z, w) = out  # A (2, 2), G (rows, 4), h (rows,), c (4,)
        A = z["A"]
        assert np.array_equal(z["G"], w["G"]) and np.array_equal(A, w["A"])
        lgv = z["G"][0, :2] @ np.linalg.inv(A)  # LGV / n_clf
        assert z["h"][0] - w["h"][0] == pytest.approx(lgv @ d, rel=1e-9, abs=1e-9)
        np.testing.assert_allclose(w["c"][:2] - z["c"][:2], 2 * A.T @ d / np.trace(A.T @ A),
                                   rtol=1e-9, atol=1e-12)
    f.inputs[1][:] = demo_ctx.clf_loop_params  # the shared buffer as the controllers set it
