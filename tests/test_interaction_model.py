"""The human-prosthesis loop restricted to the nominal human (hp_model.interaction): the walker
state it reconstructs from the prosthesis's measurements is the gait's, and its affine model
of the torque's effect is the full loop's (the human's feedback linearization + the
constrained dynamics of the 12-DOF model)."""

from __future__ import annotations

import numpy as np
import pytest

from hp_model.closed_loop import ClosedLoop
from hp_model.domains import Domain
from hp_model.interaction import InteractionModel

HUMAN = ("th_lh", "th_lk", "th_la", "th_rh")


@pytest.fixture(scope="module")
def setup(model, demo_gait):
    im = InteractionModel(model, demo_gait.degree)
    cl = ClosedLoop(model, demo_gait.degree).numeric()
    return im, cl, demo_gait


def _x_p(model, q, qd):
    k, a = model.roles[Domain.PS].prosthesis
    return np.r_[q[k], q[a], qd[k], qd[a]]


def test_walker_state_is_the_gaits_collocation_state(model, setup):
    """At every ps collocation point the reconstruction differs from the optimizer's state
    only by the human's own output errors: q_h = B(tau) + y2_h, qd_h = dB tau_dot + dy2_h
    (the collocation holds y2 = 0 at its points only to its accuracy); everything else
    (prosthesis, socket, base on the flat stance foot) is equal to solver precision."""
    im, cl, gait = setup
    theta = gait.theta(Domain.PS)
    tr = gait.trajectory[Domain.PS]
    rows = [Domain.PS.y2_coords.index(n) for n in HUMAN]
    hj = [model.coord_names.index(n) for n in HUMAN]
    worst = 0.0
    for j in range(tr["q"].shape[1]):
        q, qd = tr["q"][:, j], tr["qd"][:, j]
        qr, qdr, tau = im.walker_state(_x_p(model, q, qd), theta)
        _, y2, dy2, tau_c = cl["outputs_ps"](q, qd, theta)
        assert tau == pytest.approx(float(tau_c[0]), abs=1e-12)
        np.testing.assert_allclose(qr[hj] + y2[rows], q[hj], atol=1e-12)
        np.testing.assert_allclose(qdr[hj] + dy2[rows], qd[hj], atol=1e-10)
        worst = max(worst, float(np.abs(y2[rows]).max()))
        # the base: the prosthesis sole flat on the ground at x = 0, as in the collocation
        q_on = q.copy()
        q_on[hj] = qr[hj]
        np.testing.assert_allclose(qr, model.place_stance_foot(q_on, Domain.PS), atol=1e-12)
    assert worst < 1e-4  # the collocation's own off-surface error (rad)


def test_affine_terms_equal_the_full_loop(model, setup, rng):
    """f + g u_p and w0 + W u_p are the full loop's (xdot_human_ps: hfl + dyn_ps) prosthesis
    accelerations and stance-foot wrench, at reconstructed states along the gait and off it,
    for any motor torque."""
    im, cl, gait = setup
    theta, gains = gait.theta(Domain.PS), gait.gains_array
    tr = gait.trajectory[Domain.PS]
    k, a = model.roles[Domain.PS].prosthesis
    inter = im.numeric()["interaction_ps"]
    for j in range(0, tr["q"].shape[1], 3):
        x0 = _x_p(model, tr["q"][:, j], tr["qd"][:, j])
        for x in (x0, x0 + rng.normal(scale=(0.02, 0.02, 0.2, 0.2))):
            f, g, w0, W, _ = (o.copy() for o in inter(x, theta, gains))
            q, qd, _ = im.walker_state(x, theta)
            for u_p in (np.zeros(2), rng.normal(scale=2.0, size=2)):
                xdot, _, lam = cl["xdot_human_ps"](np.r_[q, qd], theta, gains, u_p)
                acc = np.array([xdot[12 + k], xdot[12 + a]])
                np.testing.assert_allclose(f + g @ u_p, np.r_[x[2:], acc],
                                           rtol=1e-9, atol=1e-9 * (1 + np.abs(acc).max()))
                np.testing.assert_allclose(w0 + W @ u_p, lam[:3], rtol=1e-9, atol=1e-7)


def test_torque_authority_is_the_loops_finite_difference(model, setup):
    """g's and W's columns are the full loop's response to each motor torque (central
    differences of 1 N m: the loop is affine in u_p, so only rounding remains)."""
    im, cl, gait = setup
    theta, gains = gait.theta(Domain.PS), gait.gains_array
    tr = gait.trajectory[Domain.PS]
    k, a = model.roles[Domain.PS].prosthesis
    inter = im.numeric()["interaction_ps"]
    j = tr["q"].shape[1] // 2
    x = _x_p(model, tr["q"][:, j], tr["qd"][:, j])
    _, g, _, W, _ = (o.copy() for o in inter(x, theta, gains))
    q, qd, _ = im.walker_state(x, theta)
    for col in range(2):
        e = np.zeros(2)
        e[col] = 1.0
        hi = [o.copy() for o in cl["xdot_human_ps"](np.r_[q, qd], theta, gains, e)]
        lo = [o.copy() for o in cl["xdot_human_ps"](np.r_[q, qd], theta, gains, -e)]
        dacc = (np.r_[hi[0][12 + k], hi[0][12 + a]] - np.r_[lo[0][12 + k], lo[0][12 + a]]) / 2
        np.testing.assert_allclose(g[2:, col], dacc, rtol=1e-7)
        np.testing.assert_allclose(W[:, col], (hi[2][:3] - lo[2][:3]) / 2, rtol=1e-7,
                                   atol=1e-9)
    # the paper's subsystem with the socket force held gives another authority: the
    # restricted loop's is well conditioned (the prototype: cond 51-139)
    assert np.linalg.cond(g[2:]) < 200
