"""Bezier curves, the phase variable and feedback linearization of the virtual constraints.

Exact feedback linearization makes the closed-loop output dynamics linear whatever the gait:
dy1 = -eps y1 and ddy2 = -kp y2 - kd dy2.  Simulating the full constrained model under the
controller must reproduce those solutions, which physics (not this code) fixes.
"""

from __future__ import annotations

from math import comb

import casadi as ca
import numpy as np
import pytest
from scipy.integrate import quad, solve_ivp

from hp_model import bezier
from hp_model.domains import PAPER_DOMAINS, Domain
from hp_model.outputs import GaitParams, VirtualConstraints


def test_bezier_properties(rng):
    alpha = rng.normal(size=(3, 6))
    s = np.linspace(0, 1, 11)
    B = bezier.evaluate(alpha, s)
    np.testing.assert_allclose(B[0], alpha[:, 0])  # endpoints interpolate
    np.testing.assert_allclose(B[-1], alpha[:, -1])
    np.testing.assert_allclose(bezier.basis(5, s).sum(axis=1), 1.0)  # partition of unity
    h = 1e-6
    fd = (bezier.evaluate(alpha, s[1:-1] + h) - bezier.evaluate(alpha, s[1:-1] - h)) / (2 * h)
    np.testing.assert_allclose(bezier.evaluate(bezier.derivative(alpha), s[1:-1]), fd, atol=1e-6)
    G = bezier.gram(5)
    e = rng.normal(size=6)
    val, _ = quad(lambda x: float(bezier.evaluate(e[None, :], x)[0]) ** 2, 0, 1)
    assert e @ G @ e == pytest.approx(val, rel=1e-10)
    assert comb(5, 2) == 10  # sanity on the binomial used
    # symbolic and numeric agree
    x = ca.SX.sym("x")
    f = ca.Function("b", [x], [bezier.evaluate(ca.DM(alpha), x)])
    np.testing.assert_allclose(np.array(f(0.37)).ravel(), bezier.evaluate(alpha, 0.37))


def _params(domain: str) -> GaitParams:
    # an arbitrary smooth step; the test's claims hold for any gait
    rows = {
        Domain.PS: [[0.30, 0.20, 0.0, -0.2, -0.3, -0.35], [0.2, 0.7, 1.0, 0.8, 0.3, 0.1],
               [0.1, 0.1, 0.0, 0.0, 0.0, 0.0], [-0.3, -0.2, 0.0, 0.1, 0.2, 0.25],
               [0.1, 0.1, 0.05, 0.05, 0.05, 0.05]],
        Domain.PNS: [[-0.3, -0.2, 0.0, 0.1, 0.2, 0.25], [0.1, 0.1, 0.05, 0.05, 0.05, 0.05],
                [0.30, 0.20, 0.0, -0.2, -0.3, -0.35], [0.2, 0.7, 1.0, 0.8, 0.3, 0.1],
                [0.1, 0.1, 0.0, 0.0, 0.0, 0.0]],
    }
    return GaitParams(np.array(rows[domain]), v_hip=1.0, p_min=-0.25, p_max=0.25)


@pytest.fixture(scope="module")
def vcs(model):
    return {d: VirtualConstraints(model, d, degree=5) for d in PAPER_DOMAINS}


@pytest.mark.parametrize("domain", list(PAPER_DOMAINS))
def test_phase_and_outputs_on_the_surface(model, vcs, domain):
    vc = vcs[domain]
    p = _params(domain)
    fs = vc.numeric()
    for tau in (0.0, 0.3, 0.8):
        q = vc.posture(tau, p)
        y1, y2, _, t = fs[f"outputs_{domain}"](q, np.zeros(model.nq), p.pack())
        assert t[0] == pytest.approx(tau, abs=1e-12)
        np.testing.assert_allclose(y2, 0.0, atol=1e-12)
        assert y1[0] == pytest.approx(-p.v_hip)
        # the stance foot is flat on the ground
        pose, _ = model.numeric()["frames"](q, np.zeros(model.nq))
        sole = model.domains[domain].constraints[0].target
        np.testing.assert_allclose(pose[:, model.frame_index(sole)][1:], 0.0, atol=1e-12)


@pytest.mark.parametrize("domain", list(PAPER_DOMAINS))
def test_feedback_linearization_gives_linear_output_dynamics(model, vcs, domain, rng):
    vc, p = vcs[domain], _params(domain)
    fs, mfs = vc.numeric(), model.numeric()
    fl, dyn = fs[f"fl_{domain}"], mfs[f"dyn_{domain}"]
    theta = p.pack()
    eps, kp, kd = 8.0, 100.0, 20.0  # y2 critically damped at 10 rad/s
    gains = np.array([eps, kp, kd])
    n = model.nq
    q0 = vc.posture(0.2, p)
    k = model.coord_names.index(Domain(domain).stance[0])
    q0[k] += 0.03  # off the surface (moves y2 and tau)
    q0 = model.place_stance_foot(q0, domain)
    _, _, J, _ = mfs[f"terms_{domain}"](q0, np.zeros(n))
    qd0 = rng.normal(scale=0.3, size=n)
    qd0 -= np.linalg.pinv(J) @ (J @ qd0)

    def rhs(_t, x):
        u = fl(x[:n], x[n:], theta, gains)[0].copy()
        return np.r_[x[n:], dyn(x[:n], x[n:], u)[0]]

    T = np.linspace(0, 0.3, 31)
    sol = solve_ivp(rhs, (0, 0.3), np.r_[q0, qd0], method="DOP853", rtol=1e-10, atol=1e-10,
                    t_eval=T)
    assert sol.success
    out = fs[f"outputs_{domain}"]
    ys = np.array([np.concatenate(out(x[:n], x[n:], theta)[:3]) for x in sol.y.T])
    y1, y2, dy2 = ys[:, 0], ys[:, 1:6], ys[:, 6:11]
    assert abs(y1[0]) > 0.1 and np.abs(y2[0]).max() > 0.01  # really off the surface
    np.testing.assert_allclose(y1, y1[0] * np.exp(-eps * T), atol=1e-6)
    w = 10.0
    expected = (y2[0] + (dy2[0] + w * y2[0]) * T[:, None]) * np.exp(-w * T)[:, None]
    np.testing.assert_allclose(y2, expected, atol=1e-6)
