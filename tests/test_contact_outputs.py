"""The multi-contact graph's virtual constraints (hp_model.contact_outputs): the feedback
linearization gives each domain's outputs the dynamics it promises, on states off the gait;
the regression of a trajectory onto them (characterization.gait.contact_gait)."""

from __future__ import annotations

import casadi as ca
import numpy as np
import pytest

from characterization.gait.contact_gait import fit_with_rates
from hp_model import bezier
from hp_model.config import default_device_path, default_subject_path, load_device, load_subject
from hp_model.contact_outputs import (
    PERSON_MIN_LOAD,
    PERSON_MU,
    ContactConstraints,
    virtual_constraints,
)
from hp_model.domains import Domain, DomainGraph
from hp_model.human_prosthesis import HumanProsthesisModel
from hp_model.outputs import VirtualConstraints

GAINS = np.array([10.0, 1600.0, 80.0])


@pytest.fixture(scope="module")
def model() -> HumanProsthesisModel:
    return HumanProsthesisModel(load_subject(default_subject_path()),
                                load_device(default_device_path()),
                                graph=DomainGraph.MULTICONTACT)


def _state(rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """A walking-like posture (hip over the feet, knees bent) with random velocities."""
    q = np.zeros(12)
    q[1] = 0.9
    q[[3, 4, 5, 6, 10, 11]] = [-0.3, 0.3, -0.05, 0.2, 0.2, -0.1]
    q[[3, 4, 5, 6, 10, 11]] += 0.05 * rng.standard_normal(6)
    qd = 0.5 * rng.standard_normal(12)
    qd[7:10] = 0.0  # the socket's fixed joint
    return q, qd


def _theta(vc: ContactConstraints, rng: np.random.Generator) -> np.ndarray:
    """Curves near the posture, a hip progress of 0.2 m at about 1.2 m/s."""
    L, d = vc.layout, vc.domain
    alpha = 0.2 * rng.standard_normal((L.rows, L.degree + 1))
    if d.velocity_output:
        alpha[len(d.y2_coords)] = 1.2 + 0.1 * rng.standard_normal(L.degree + 1)
    if d.is_double_support:  # the leading contact's friction ratio
        alpha[-1] = 0.1 * rng.standard_normal(L.degree + 1)
    return np.r_[alpha.ravel(), 1.2, -0.1, 0.1]


def _stacked(vc: ContactConstraints, q, qd, qdd, u, theta, share: float = 1.0
             ) -> np.ndarray:
    """The closed loop's error per row of the stack with ``share`` of the feedback applied:
    dy1 + s eps y1 (where there is y1), ddy2 + s (kp y2 + kd dy2), and in a double support
    the squeeze row's F_x - R(tau) F_z (N, divided by 100 to be of the rows' size)."""
    y1, y2, dy2, dy1_num, _, ddy2_num = _output_rates(vc, q, qd, qdd, theta)
    rows = ddy2_num + share * (GAINS[1] * y2 + GAINS[2] * dy2)
    if vc.domain.velocity_output:
        rows = np.r_[dy1_num + share * GAINS[0] * y1, rows]
    if vc.squeeze is not None:
        rows = np.r_[rows, float(vc.squeeze(q, qd, theta, u)[0]) / 100.0]
    return rows


def _output_rates(vc: ContactConstraints, q, qd, qdd, theta) -> tuple[np.ndarray, ...]:
    """(y1, y2, dy2) and their time derivatives, the latter by central differences along
    (qd, qdd) (step 1e-6 s: error ~1e-9 of the second derivatives here)."""
    f = vc.functions[f"outputs_{vc.domain}"]
    h = 1e-6

    def at(s: float) -> tuple[np.ndarray, ...]:
        y1, y2, dy2, _ = f(q + s * qd + 0.5 * s * s * qdd, qd + s * qdd, theta)
        return float(y1), np.array(y2).ravel(), np.array(dy2).ravel()

    (y1p, y2p, dy2p), (y1m, y2m, dy2m), (y1, y2, dy2) = at(h), at(-h), at(0.0)
    return y1, y2, dy2, (y1p - y1m) / (2 * h), (y2p - y2m) / (2 * h), (dy2p - dy2m) / (2 * h)


def _fl_at_random_state(model: HumanProsthesisModel, domain: Domain, seed: int):
    """(constraints, dynamics, q, qd, theta, fl's torques) at a random state and curves."""
    rng = np.random.default_rng(seed)
    vc = ContactConstraints(model, domain, degree=4)
    dyn = model.function(f"dyn_{domain}")
    q, qd = _state(rng)
    theta = _theta(vc, rng)
    u = np.array(vc.functions[f"fl_{domain}"](q, qd, theta, GAINS)[0]).ravel()
    return vc, dyn, q, qd, theta, u


@pytest.mark.parametrize("domain", list(DomainGraph.MULTICONTACT.domains))
def test_feedback_linearization_gives_the_outputs_their_dynamics(
        model: HumanProsthesisModel, domain: Domain) -> None:
    """fl: dy1 = -eps y1 (where there is y1) and ddy2 = -kp y2 - kd dy2, with qdd from the
    domain's constrained dynamics; hfl: the same on the human's rows whatever u_p."""
    vc, dyn, q, qd, theta, u = _fl_at_random_state(model, domain, seed=7)
    share = float(vc.functions[f"feedback_{domain}"](q, qd, theta, GAINS)[2])
    qdd = np.array(dyn(q, qd, u)[0]).ravel()
    _, y2, dy2, _, dy2_num, ddy2_num = _output_rates(vc, q, qd, qdd, theta)
    np.testing.assert_allclose(dy2_num, dy2, atol=1e-7)  # dy2 is y2's rate
    scale = np.abs(GAINS[1] * y2).max()
    np.testing.assert_allclose(ddy2_num, -share * (GAINS[1] * y2 + GAINS[2] * dy2),
                               atol=1e-6 * scale)
    stacked = _stacked(vc, q, qd, qdd, u, theta, share)
    np.testing.assert_allclose(stacked, 0.0, atol=1e-6 * scale)  # y1 and the squeeze too
    # the human's feedback linearization, the prosthesis torque given
    u_p = np.array([3.0, -2.0])
    u_h = np.array(vc.functions[f"hfl_{domain}"](q, qd, theta, GAINS, u_p)).ravel()
    h_share = float(vc.functions[f"hfeedback_{domain}"](q, qd, theta, GAINS, u_p)[2])
    np.testing.assert_array_equal(u_h[4:], u_p)
    qdd = np.array(dyn(q, qd, u_h)[0]).ravel()
    closed = _stacked(vc, q, qd, qdd, u_h, theta, h_share)
    rows = list(domain.human_outputs)
    np.testing.assert_allclose(closed[rows], 0.0, atol=1e-6 * scale)
    assert np.abs(closed[[r for r in range(closed.size) if r not in rows]]).max() > 1e-3, \
        "the prosthesis's rows are not the human's to hold"


@pytest.mark.parametrize("domain", list(DomainGraph.MULTICONTACT.domains))
def test_the_human_given_the_oracles_prosthesis_torque_is_the_oracle(
        model: HumanProsthesisModel, domain: Domain) -> None:
    """hfl given the u_p that fl computes returns fl's six torques at fl's share of the
    feedback (so a prosthesis that applies the oracle's torque walks the oracle's walk while
    neither yields); the human's own share is at least fl's (fl's point keeps its contacts,
    and the human's line through it yields no sooner).  In a double support (a closed
    chain: one torque direction only presses the legs against each other and moves nothing)
    that squeeze is a row of its own, the leading contact's F_x / F_z on its curve; in
    ``ds_h`` the human holds it whatever u_p, in ``ds_p`` the prosthesis's torque sets it
    (hp_model.contact_outputs: the human's rows with it go singular there)."""
    vc, dyn, q, qd, theta, u = _fl_at_random_state(model, domain, seed=11)
    share = float(vc.functions[f"feedback_{domain}"](q, qd, theta, GAINS)[2])
    h_ff, h_fb, h_share = (np.array(a).ravel() for a in vc.functions[f"hfeedback_{domain}"](
        q, qd, theta, GAINS, u[4:]))
    np.testing.assert_allclose(h_ff + share * h_fb, u, rtol=1e-7, atol=1e-7 * np.abs(u).max())
    assert h_share.item() >= share - 1e-9
    u_h = np.array(vc.functions[f"hfl_{domain}"](q, qd, theta, GAINS, u[4:])).ravel()
    np.testing.assert_allclose(u_h, h_ff + h_share.item() * h_fb, rtol=1e-12, atol=1e-9)
    if not domain.is_double_support:
        return
    # the null direction, numerically: torques that leave every acceleration unchanged
    B = np.column_stack([np.array(dyn(q, qd, e)[0]).ravel() - np.array(dyn(q, qd, 0 * e)[0]).ravel()
                         for e in np.eye(6)])  # d qdd / d u (12, 6)
    _, sv, vt = np.linalg.svd(B)
    assert sv[-1] < 1e-9 * sv[0]  # one squeeze direction
    assert vc.squeeze is not None
    assert abs(float(vc.squeeze(q, qd, theta, u)[0])) < 1e-6 * np.abs(u).max()
    squeezed = u + 50.0 * vt[-1]  # the same motion, another squeeze: another friction ratio
    assert abs(float(vc.squeeze(q, qd, theta, squeezed)[0])) > 1.0
    human = 5 in domain.human_outputs  # the squeeze's row (after y1 and four y2 rows)
    assert human == (domain == Domain.DS_H)
    for u_p in ([3.0, -2.0], [-1.0, 0.5]):
        u_h = np.array(vc.functions[f"hfl_{domain}"](q, qd, theta, GAINS, u_p)).ravel()
        err = abs(float(vc.squeeze(q, qd, theta, u_h)[0]))
        assert (err < 1e-6 * np.abs(u_h).max()) if human else (err > 1.0), (u_p, err)


def test_phase_is_the_hip_over_the_stance_contact(model: HumanProsthesisModel) -> None:
    """tau = (x_hip - x_contact - p_min) / (p_max - p_min), the contact the domain's first."""
    rng = np.random.default_rng(3)
    q, _ = _state(rng)
    frames = model.function("frames")
    pose = np.array(frames(q, np.zeros(12))[0])
    for d in DomainGraph.MULTICONTACT.domains:
        vc = ContactConstraints(model, d, degree=3)
        theta = _theta(vc, rng)
        x_c = pose[0, model.frame_index(d.contacts[0].frame)]
        expect = (pose[0, model.frame_index("hip")] - x_c + 0.1) / 0.2
        assert vc.phase(q, theta) == pytest.approx(expect, abs=1e-12)


def test_the_graph_picks_its_constraints(model: HumanProsthesisModel) -> None:
    paper = HumanProsthesisModel(model.subject, model.device)
    assert isinstance(virtual_constraints(paper, Domain.PS, 5), VirtualConstraints)
    assert isinstance(virtual_constraints(model, Domain.DS_H, 5), ContactConstraints)
    with pytest.raises(ValueError, match="not in the paper graph"):
        ContactConstraints(paper, Domain.DS_H)


def test_regression_with_slopes_recovers_a_curve() -> None:
    """Nodes and slopes of a degree-5 curve give back its coefficients; noise on the
    values alone moves the curve's ends less than a plain fit's."""
    rng = np.random.default_rng(11)
    alpha = rng.standard_normal((2, 6))
    tau = np.linspace(0.0, 1.0, 17)
    y = bezier.evaluate(alpha, tau)  # (17, 2)
    dy = bezier.evaluate(bezier.derivative(alpha), tau)
    np.testing.assert_allclose(fit_with_rates(tau, y, dy, 5), alpha, atol=1e-10)
    noisy = y + 0.01 * rng.standard_normal(y.shape)
    ends = np.abs(bezier.evaluate(fit_with_rates(tau, noisy, dy, 5), np.array([0.0, 1.0]))
                  - bezier.evaluate(alpha, np.array([0.0, 1.0])))
    assert ends.max() < 0.02


def test_symbolic_functions_are_sx(model: HumanProsthesisModel) -> None:
    """Generated as C like the paper's (SX, no free symbols)."""
    vc = ContactConstraints(model, Domain.PS_TOE, degree=3)
    for f in vc.functions.values():
        assert f.is_a("SXFunction") and not f.has_free()
    assert isinstance(vc.functions["fl_ps_toe"].sx_in(0), ca.SX)


@pytest.mark.parametrize("domain", list(DomainGraph.MULTICONTACT.domains))
def test_the_person_yields_its_feedback_to_its_contacts(
        model: HumanProsthesisModel, domain: Domain) -> None:
    """Over random states, the margin rows of every contact (mu F_z - F_x, mu F_z + F_x,
    F_z - min load with PERSON_MU, and PERSON_MIN_LOAD on the stance contact, 0 on a double
    support's trailing one; >= 0 inside) under the torques fl
    applies, u_ff + s u_fb: each row the feedback lowers that held without it still holds;
    s < 1 only where such a row is on its margin at s (or already off it without feedback:
    s = 0); s = 1 otherwise (the paper's law)."""
    rng = np.random.default_rng(3)
    vc = ContactConstraints(model, domain, degree=4)
    fs, dyn = vc.functions, model.function(f"dyn_{domain}")
    yielded = 0

    def rows(q, qd, torques):
        lam, out, r = np.array(dyn(q, qd, torques)[1]).ravel(), [], 0
        for k, c in enumerate(domain.contacts):  # the stance contact's load, the other's >= 0
            fx, fz = lam[r], lam[r + 1]
            out += [PERSON_MU * fz - fx, PERSON_MU * fz + fx,
                    fz - (PERSON_MIN_LOAD if k == 0 else 0.0)]
            r += c.size
        return np.array(out)

    for _ in range(40):
        q, qd = _state(rng)
        theta = _theta(vc, rng)
        u_ff, u_fb, share = (np.array(a).ravel() for a in fs[f"feedback_{domain}"](
            q, qd, theta, GAINS))
        s = share.item()
        u = np.array(fs[f"fl_{domain}"](q, qd, theta, GAINS)[0]).ravel()
        np.testing.assert_allclose(u, u_ff + s * u_fb, rtol=1e-12, atol=1e-9)
        g0, g1, g = rows(q, qd, u_ff), rows(q, qd, u_ff + u_fb), rows(q, qd, u)
        tol = 1e-6 * max(np.abs(g0).max(), np.abs(g1).max())
        lowered = g1 < g0 - tol
        assert np.all(g[lowered & (g0 >= 0)] >= -tol)  # held without feedback: still holds
        assert 0.0 <= s <= 1.0
        if s < 1.0:
            yielded += 1
            on_margin = np.abs(g[lowered]).min() <= tol if lowered.any() else False
            assert on_margin or (s == 0.0 and np.any(g0[lowered] < 0)), (s, g0, g1, g)
    assert yielded  # the test saw the person yield
