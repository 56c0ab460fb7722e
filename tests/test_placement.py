"""The one owner of the walker's phase, outputs and placement (hp_model.outputs,
hp_model.placement, hp_model.domains): its formulas against the paper's written by hand, its
numeric and generated forms against each other, and what a placed state satisfies."""

from __future__ import annotations

import numpy as np
import pytest

from hp_model.closed_loop import ClosedLoop
from hp_model.domains import PAPER_DOMAINS, PROSTHESIS, Domain
from hp_model.outputs import GaitParams, HipProgress, ThetaLayout


@pytest.fixture(scope="module")
def loop(model, template_gait):
    return ClosedLoop(model, template_gait.degree)


def test_roles_are_the_tables_resolved_to_indices(model):
    idx = model.coord_names.index
    for d in PAPER_DOMAINS:
        r = model.roles[d]
        assert (r.name, r.code, r.next) == (d, Domain(d).code, Domain.from_code(1 - Domain(d).code))
        assert (r.knee, r.ankle) == tuple(idx(n) for n in Domain(d).stance)
        assert r.y2 == tuple(idx(n) for n in Domain(d).y2_coords)
        assert r.stance_frame_index == model.frame_index(model.stance_frame(d))
        assert r.swing_frame == model.domains[d].swing_frame
        assert r.prosthesis == tuple(idx(n) for n in PROSTHESIS)
        assert r.human_rows == Domain(d).human_outputs
        for i, row in zip(r.on_outputs, r.on_outputs_rows, strict=True):
            assert r.y2[row] == i and i not in (r.knee, *r.prosthesis)
    assert model.roles[Domain.PS].on_outputs == tuple(idx(n) for n in ("th_lh", "th_lk", "th_la",
                                                                  "th_rh"))
    assert model.roles[Domain.PNS].prosthesis_rows == (3, 4)
    assert model.roles[Domain.PS].prosthesis_rows == (4, -1)


def test_theta_layout_packs_and_unpacks_the_gait(template_gait):
    p = template_gait.params[Domain.PS]
    th = p.pack()
    L = ThetaLayout.of_size(th.size)
    assert p.layout == L and L.size == th.size == 5 * (p.degree + 1) + 3
    assert (th[L.v_hip], th[L.p_min], th[L.p_max]) == (p.v_hip, p.p_min, p.p_max)
    assert np.array_equal(th[L.progress], [p.v_hip, p.p_min, p.p_max])
    for r in range(5):
        assert np.array_equal(th[L.row(r)], p.alpha[r])
    for q in (GaitParams.unpack(th), GaitParams.unpack(th, p.degree)):
        assert np.array_equal(q.alpha, p.alpha) and q.pack().tobytes() == th.tobytes()
    with pytest.raises(ValueError):
        ThetaLayout.of_size(th.size + 1)


def test_phase_is_the_papers_formula_in_every_form(model, loop, template_gait, rng):
    """tau = (c_k th_k + c_a th_a - p_min) / (p_max - p_min) written out here; the numeric
    owner computes exactly it, and the generated phase_<d> (the FMU's) the same bits."""
    for d in PAPER_DOMAINS:
        vc, th = loop.vcs[d], template_gait.theta(d)
        p = template_gait.params[d]
        ck, ca = model.hip_progress_coefficients(d)
        k, a = (model.coord_names.index(n) for n in Domain(d).stance)
        f = loop.numeric()[f"phase_{d}"]
        for _ in range(200):
            q = rng.normal(scale=0.5, size=model.nq)
            by_hand = (ck * q[k] + ca * q[a] - p.p_min) / (p.p_max - p.p_min)
            assert vc.phase(q, th) == by_hand == vc.phase(q, p)
            assert float(f(q, th)[0][0]) == by_hand
            assert vc.stance_phase(q[k], q[a], th) == by_hand
            assert HipProgress(ck, ca).phase(q[k], q[a], p.p_min, p.p_max) == by_hand
        assert vc.phase_rate(q, th) == pytest.approx((ck * q[k] + ca * q[a])
                                                     / (p.p_max - p.p_min), rel=1e-15)
        assert p.phase_of(p.delta_p_at(0.37)) == pytest.approx(0.37, abs=1e-15)
        assert p.nominal_duration == pytest.approx((p.p_max - p.p_min) / p.v_hip, rel=1e-15)
        assert p.nominal_rate * p.nominal_duration == pytest.approx(1.0, rel=1e-15)


def _foot_at_rest(model, d, q, qd, x):
    pose, vel = model.numeric()["frames"](q, qd)
    i = model.frame_index(model.stance_frame(d))
    np.testing.assert_allclose(pose[:, i], [x, 0.0, 0.0], atol=1e-12)
    np.testing.assert_allclose(vel[:, i], 0.0, atol=1e-12)


def test_the_posture_is_on_the_outputs_and_its_foot_at_rest(model, loop, template_gait):
    for d in PAPER_DOMAINS:
        vc, p = loop.vcs[d], template_gait.params[d]
        for tau in (0.1, 0.5, 0.9):
            q, qd = loop.zero_dynamics_state(d, tau, p.pack())
            y1, y2, dy2, t = loop.numeric()[f"outputs_{d}"](q, qd, p.pack())
            assert abs(float(t[0]) - tau) < 1e-12 and abs(float(y1[0])) < 1e-12
            assert np.abs(y2).max() < 1e-12 and np.abs(dy2).max() < 1e-12
            _foot_at_rest(model, d, q, qd, 0.0)
            np.testing.assert_allclose(vc.posture(tau, p), q, atol=1e-15)
            np.testing.assert_allclose(vc.posture_rate(tau, p.nominal_rate, p), qd,
                                       atol=1e-12)


def test_a_start_moves_the_prosthesis_and_puts_the_human_on_its_outputs(model, loop,
                                                                       template_gait):
    """start_<d> (the scenarios' and the FMU's offsets): zero offsets keep the state; an
    offset moves th_pk and th_pa by it, the other human y2 joints onto their outputs at the
    new phase, the stance foot flat where it was and at rest."""
    for d in PAPER_DOMAINS:
        tr, th, r = template_gait.trajectory[d], template_gait.theta(d), model.roles[d]
        q0, qd0 = tr["q"][:, 0], tr["qd"][:, 0]
        q, qd = loop.start_state(d, q0, qd0, th)
        assert q.tobytes() == q0.tobytes() and qd.tobytes() == qd0.tobytes()
        off = np.array([0.03, -0.02])
        q, qd = loop.start_state(d, q0, qd0, th, off)
        np.testing.assert_allclose(q[list(r.prosthesis)], q0[list(r.prosthesis)] + off,
                                   atol=1e-15)
        assert np.array_equal(qd[list(r.prosthesis)], qd0[list(r.prosthesis)])
        _, y2, dy2, _ = loop.numeric()[f"outputs_{d}"](q, qd, th)
        rows = list(r.on_outputs_rows)
        assert np.abs(y2[rows]).max() < 1e-12 and np.abs(dy2[rows]).max() < 1e-12
        x0 = model.numeric()["frames"](q0, qd0)[0][0, r.stance_frame_index]
        _foot_at_rest(model, d, q, qd, x0)
        # the placement alone keeps the joints and moves the base
        qp, qdp = model.stance_state(q0, qd0, d, 0.5)
        assert np.array_equal(qp[3:], q0[3:]) and np.array_equal(qdp[3:], qd0[3:])
        _foot_at_rest(model, d, qp, qdp, 0.5)
