"""The socket wrench F_s: the paper's formula, the full KKT solve, the subsystem, statics."""

from __future__ import annotations

import numpy as np
import pytest

from hp_model.domains import PAPER_DOMAINS, Domain
from hp_model.statics import standing_posture, static_equilibrium
from tests.conftest import random_state


@pytest.mark.parametrize("dom", list(PAPER_DOMAINS))
def test_paper_formula_equals_kkt_socket_rows(model, rng, dom):
    """eq. (Fsocket) with the stance-foot wrench on the known side = the KKT's socket rows."""
    fs = model.numeric()
    sl = model.domains[dom].wrench_slice("socket")
    fl = model.domains[dom].wrench_slice(model.domains[dom].constraints[0].name)
    paper = model.function(f"socket_{dom}")
    for _ in range(30):
        q, qd = random_state(model, rng)
        u = rng.normal(scale=3.0, size=model.nu)
        _, lam = fs[f"dyn_{dom}"](q, qd, u)
        Fs = np.array(paper(q, qd, u, lam[fl])).ravel()
        np.testing.assert_allclose(Fs, lam[sl], rtol=1e-9, atol=1e-9 * np.abs(lam).max())


def test_subsystem_reproduces_full_prosthesis_motion(model, subsystem, rng):
    """Driving the 5-DOF subsystem with the full model's F_s (and the same prosthesis
    torques) gives the full model's prosthesis accelerations and ground reaction."""
    fs, sfs = model.numeric(), subsystem.numeric()
    for _ in range(50):
        q, qd = random_state(model, rng)
        u = rng.normal(scale=3.0, size=model.nu)
        qdd, lam = (a.copy() for a in fs["dyn_ps"](q, qd, u))
        qb, qbd, qbdd = subsystem.from_full(q, qd, qdd)
        qbdd_sub, lam_sub = sfs["sub_dyn"](qb, qbd, u[4:], lam[3:6])
        scale = max(1.0, np.abs(qbdd).max())
        np.testing.assert_allclose(qbdd_sub, qbdd, atol=1e-9 * scale)
        np.testing.assert_allclose(lam_sub, lam[0:3], atol=1e-8 * max(1.0, np.abs(lam).max()))


def test_a_different_socket_force_gives_a_different_motion(model, subsystem, rng):
    """Guard against a vacuous comparison: F_s must matter to the subsystem."""
    fs, sfs = model.numeric(), subsystem.numeric()
    q, qd = random_state(model, rng)
    u = np.zeros(model.nu)
    qdd, lam = (a.copy() for a in fs["dyn_ps"](q, qd, u))
    qb, qbd, qbdd = subsystem.from_full(q, qd, qdd)
    wrong = lam[3:6] + np.array([20.0, 0.0, 0.0])
    assert np.abs(sfs["sub_dyn"](qb, qbd, u[4:], wrong)[0] - qbdd).max() > 1e-3


def test_reduced_form_matches_subsystem_kkt(subsystem, rng):
    """x_p_dot = f_p + g_m u + g_s F_s equals the constrained 5-DOF dynamics at embedded
    states (sole flat at the origin), for any u and F_s (the form is affine and exact)."""
    sfs = subsystem.numeric()
    for _ in range(50):
        xp = np.r_[rng.normal(scale=0.5, size=2), rng.normal(scale=2.0, size=2)]
        qb, qbd = (a.copy() for a in sfs["embed"](xp))
        pose, vel = sfs["frames"](qb, qbd)
        i = subsystem.frame_index("p_sole")
        np.testing.assert_allclose(pose[:, i], 0.0, atol=1e-12)
        np.testing.assert_allclose(vel[:, i], 0.0, atol=1e-12)
        f, gm, gs = (a.copy() for a in sfs["reduced"](xp))
        u, F = rng.normal(size=2), rng.normal(scale=300.0, size=3)
        qdd, _ = sfs["sub_dyn"](qb, qbd, u, F)
        np.testing.assert_allclose((f + gm @ u + gs @ F)[2:], qdd[3:5], rtol=1e-9,
                                   atol=1e-9 * max(1.0, np.abs(qdd).max()))
        np.testing.assert_allclose((f + gm @ u + gs @ F)[:2], xp[2:], atol=0)


@pytest.mark.parametrize("dom", list(PAPER_DOMAINS))
def test_static_stance_socket_force_is_the_weight_above_the_socket(model, dom):
    """Upright and still: the ground carries M g; in ps the socket carries everything above
    it, F_z = -(M - m_prosthesis) g; in pns the socket holds the hanging prosthesis,
    F_z = +m_prosthesis g (the human pulls up).  Newton's law fixes both."""
    g, M, mp = model.tree.gravity, model.tree.total_mass, model.prosthesis_mass
    q = standing_posture(model)
    _, lam = static_equilibrium(model, dom, q)
    foot, sock = lam[0:3], lam[3:6]
    assert foot[1] == pytest.approx(M * g, rel=1e-9)
    assert foot[0] == pytest.approx(0.0, abs=1e-9)
    expected = -(M - mp) * g if dom == Domain.PS else mp * g
    assert sock[1] == pytest.approx(expected, rel=1e-9)
    assert sock[0] == pytest.approx(0.0, abs=1e-9)


def test_hip_progress_increases_as_the_shank_rolls_over_the_foot(model):
    """delta_p_hip linearises the hip's forward position over the stance ankle."""
    ck, ca_ = model.hip_progress_coefficients(Domain.PS)
    p = model.device.prosthesis
    above_knee = model.subject.lengths.thigh + model.device.iwalk.length.value + p.top.length.value
    assert ck == pytest.approx(-above_knee, rel=1e-12)
    assert ca_ == pytest.approx(-(above_knee + p.shin.length.value), rel=1e-12)
    # exact forward kinematics agree to first order
    fs = model.numeric()
    for th_k, th_a in [(0.01, -0.02), (-0.015, 0.005)]:
        q = np.zeros(model.nq)
        q[10], q[11] = th_k, th_a
        q = model.place_stance_foot(q, Domain.PS)
        pose, _ = fs["frames"](q, np.zeros(model.nq))
        dx = pose[0, model.frame_index("hip")] - pose[0, model.frame_index("p_ankle")]
        assert dx == pytest.approx(ck * th_k + ca_ * th_a, abs=1e-3 * 0.02)
