"""The QP solver cross-checked: piqp (dense, whitened variables, as the controllers run it)
against quadprog (Goldfarb-Idnani dual active set, on the u-space form) on thousands of QP
instances built from random prosthesis states, for the exact QP with and without torque
bounds and the relaxed QP with random previous torques (rate bounds) and rho."""

from __future__ import annotations

import numpy as np
import pytest
import quadprog

from prosthesis_controller import ClfConfig, ControllerConfig, ControllerContext, make_controller
from prosthesis_controller.interface import QpOutcome
from tests.controller_support import stance_meas, tube_about_nominal

N_STATES = 1500
# torques are ~1 N m (motor); 1e-6 N m = 5e-5 N m at the joint, far below any effect
TOL_U = 1e-6


def _box_rows(xl, xu):
    """quadprog rows (C^T x >= b) of finite box bounds."""
    C, b = [], []
    for i, (lo, hi) in enumerate(zip(xl, xu, strict=True)):
        e = np.zeros(len(xl))
        e[i] = 1.0
        if np.isfinite(lo):
            C.append(e)
            b.append(lo)
        if np.isfinite(hi):
            C.append(-e)
            b.append(-hi)
    return C, b


def _qp(P, c, rows, rhs):
    """quadprog: min 1/2 u^T P u + c^T u  s.t. rows u >= rhs.  None if infeasible."""
    try:
        sol = quadprog.solve_qp(P, -c, np.array(rows).T, np.array(rhs), 0)
    except ValueError:  # "constraints are inconsistent, no solution"
        return None
    return sol[0], sol[1]


def solve_exact(P, c, G, h, xl, xu):
    C, b = _box_rows(xl, xu)
    out = _qp(P, c, [-G[0], *C], [-h[0], *b])
    return None if out is None else out[0]


def solve_relaxed(P, c, G, h, xl, xu):
    """z = (u, rho) with rho only in the cost (c_rho rho) and the row (g u - k rho <= h):
    for fixed u the best rho is max(0, (g u - h)/k), so the optimum is the better of
    (A) rho = 0, g u <= h and (B) h <= g u <= h + k rho_max with the cost plus
    c_rho (g u - h) / k -- two strictly convex QPs in u."""
    Pu, cu, cr = P[:2, :2], c[:2], c[2]
    g, k, rho_max = G[0, :2], -G[0, 2], xu[2]
    C, b = _box_rows(xl[:2], xu[:2])
    best = None
    a = _qp(Pu, cu, [-g, *C], [-h[0], *b])
    if a is not None:
        best = (a[1], a[0], 0.0)
    bb = _qp(Pu, cu + cr * g / k, [g, -g, *C], [h[0], -(h[0] + k * rho_max), *b])
    if bb is not None:
        val = bb[1] - cr * h[0] / k
        if best is None or val < best[0]:
            best = (val, bb[0], max(0.0, (g @ bb[0] - h[0]) / k))
    return None if best is None else (best[1], best[2])


@pytest.fixture(scope="module")
def contexts(model, subsystem, template_gait):
    tube = tube_about_nominal(template_gait, (40.0, 60.0, 8.0))
    mk = {
        "exact": ClfConfig(),
        "exact-bounded": ClfConfig(exact_limits_in_qp=True),
        "relaxed": ClfConfig(),
    }
    return {k: ControllerContext(template_gait, tube, model, ControllerConfig(clf=v),
                                 subsystem=subsystem) for k, v in mk.items()}


def random_states(ctx, n, rng):
    tr = ctx.gait.trajectory["ps"]
    i = [ctx.model.coord_names.index(c) for c in ("th_pk", "th_pa")]
    k = rng.integers(0, tr["q"].shape[1], n)
    x = np.r_[tr["q"][i][:, k], tr["qd"][i][:, k]].T
    return x + rng.normal(size=(n, 4)) * np.array([0.03, 0.03, 0.7, 0.7])


@pytest.mark.parametrize("variant", ["exact", "exact-bounded", "relaxed"])
def test_piqp_agrees_with_quadprog_on_random_instances(contexts, variant):
    ctx = contexts[variant]
    name = "clfqp-paper" if variant == "relaxed" else "clfqp-paper-exact"
    ctl = make_controller(name, None, None, None, context=ctx)
    rng = np.random.default_rng({"exact": 1, "exact-bounded": 2, "relaxed": 3}[variant])
    lim = np.array(ctx.limits)
    counts = {"solved": 0, "infeasible": 0, "active_bound": 0}
    worst = 0.0
    for x in random_states(ctx, N_STATES, rng):
        ctl.reset(rng.uniform(-lim, lim))
        out = ctl.tick(stance_meas(0.0, x))
        data = ctl.qp_data()
        ref = (solve_relaxed if variant == "relaxed" else solve_exact)(*data)
        if out.diagnostics.qp_status == QpOutcome.INFEASIBLE:
            assert ref is None, "the feasibility test refused a feasible QP"
            counts["infeasible"] += 1
            continue
        assert out.diagnostics.qp_status == QpOutcome.SOLVED
        assert ref is not None, "piqp solved a QP that quadprog finds infeasible"
        u_ref = ref[0] if variant == "relaxed" else ref
        u = ctl.qp_solution[:2]
        err = float(np.max(np.abs(u - u_ref)))
        worst = max(worst, err)
        assert err <= TOL_U, (x, u, u_ref)
        if variant == "relaxed":
            g, k = data[2][0, :2], -data[2][0, 2]
            # rho is fixed by u through the row: |d rho| <= |g| |du| / k
            tol_rho = TOL_U * (1 + np.linalg.norm(g) / k)
            assert ctl.qp_solution[2] == pytest.approx(ref[1], abs=tol_rho)
        counts["solved"] += 1
        counts["active_bound"] += bool(out.diagnostics.active & 0b11110)
    # the instances exercise the cases they should
    assert counts["solved"] >= N_STATES // 2
    if variant != "exact":
        assert counts["active_bound"] > 50
    print(variant, counts, f"max |u_piqp - u_quadprog| = {worst:.2e}")
