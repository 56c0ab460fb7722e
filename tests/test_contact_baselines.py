"""The paper's baselines on the multi-contact graph (prosthesis_controller.pd, .passive):
``pd``'s stance is the paper's joint PD about the gait at contact-pd's phase, ``passive``'s
Spong's law about the gait's angles, rates and accelerations there; both swing as
contact-pd; the reference accelerations; ``pd`` walking the packaged person's gait in the
in-process plant."""

from __future__ import annotations

import math
from pathlib import Path

import casadi as ca
import numpy as np
import pytest

from characterization.gait.contact_gait import GAINS
from characterization.gait.person_synth import REFERENCE_PERSON_GAIT
from hp_model.prosthesis import ProsthesisSubsystem
from orchestrator.cosim.contact_controllers import (
    LoopSetup,
    held_walk,
    load_contact_run,
    loop_simulator,
    make_baseline,
    make_contact_pd,
    make_controller,
)
from orchestrator.experiments.contact_walk import controller_run
from prosthesis_controller.config import PassiveConfig, PdConfig
from prosthesis_controller.measurement import ProsthesisMeasurement
from prosthesis_controller.passive import (
    ContactPassive,
    PassiveLaw,
    stance_accelerations,
)
from prosthesis_controller.terms import reduced_lagrangian, regressor, standard_parameters

pytestmark = pytest.mark.slow  # the packaged person's model, compiled once


@pytest.fixture(scope="module")
def person():
    run = load_contact_run(Path(REFERENCE_PERSON_GAIT))
    sim = loop_simulator(run.model, run.gait, GAINS)
    setup = LoopSetup(sim, held_walk(sim, run.trajectory))
    return run, sim, setup


def _measurement(t: float, contact: bool, q=(0.3, -0.05), qd=(0.5, -1.0)):
    return ProsthesisMeasurement(t, q[0], q[1], qd[0], qd[1], 600.0 if contact else 0.0,
                                 contact, 0.25)


def test_pd_is_the_papers_joint_pd_in_stance_and_contact_pds_swing(person) -> None:
    """Stance: kp (q_d - q) + kd (qd_d - qd) with the paper's PdConfig gains about the stance
    table at the phase, no torque of the gait's; swing: contact-pd's torque on the same
    measurements."""
    run, _, setup = person
    pd = make_baseline("pd", run.model, run.gait, run.trajectory, setup)
    ref_law = make_contact_pd(run.model, run.gait, run.trajectory, setup)
    cfg = PdConfig()
    (gk, ga), (lk, la) = pd.gear, pd.limits
    for law in (pd, ref_law):
        law.reset()
    m = _measurement(0.1, True)
    u = pd.tick(m).torque
    ref_law.tick(m)
    rk, ra, rvk, rva, fk, fa = pd.tables.stance.at(pd.phase)
    assert abs(fk) + abs(fa) > 0.05  # the gait has a torque there, which pd leaves out
    want = (cfg.kp[0] * (rk - m.knee_angle) + cfg.kd[0] * (rvk - m.knee_vel)) / gk, \
        (cfg.kp[1] * (ra - m.ankle_angle) + cfg.kd[1] * (rva - m.ankle_vel)) / ga
    assert u[0] == pytest.approx(min(max(want[0], -lk), lk), abs=1e-12)
    assert u[1] == pytest.approx(min(max(want[1], -la), la), abs=1e-12)
    for t in (0.101, 0.2, 0.35):  # a swing from toe-off at 0.101 s
        s = _measurement(t, False, (0.6, 0.1), (-2.0, 0.5))
        np.testing.assert_allclose(pd.tick(s).torque, ref_law.tick(s).torque, atol=1e-12)


def test_passive_is_spongs_law_about_the_gait_at_its_phase(person) -> None:
    """rho = 0: u = M (qdd_d - L e') + C (qd_d - L e) + g - K (e' + L e) (joint side, the
    flat-foot stance prosthesis's M, C, g evaluated from their symbolic form), over the gear;
    with rho > 0 the robust term moves it by at most rho |Y_links| and the drives' armature
    columns are not in it."""
    run, _, setup = person
    base = make_baseline("passive", run.model, run.gait, run.trajectory, setup)
    assert isinstance(base, ContactPassive)
    sub = ProsthesisSubsystem(run.model)
    xs, M, g, C = reduced_lagrangian(sub)
    a_s, v_s = ca.SX.sym("a", 2), ca.SX.sym("v", 2)
    mcg = ca.Function("mcg", [xs, a_s, v_s], [M @ a_s + C @ v_s + g])
    Y, links = regressor(sub, xs, a_s, v_s)
    n_links = 4 * len(links)
    Yf = ca.Function("Y", [xs, a_s, v_s], [Y])
    assert Y.shape[1] == len(standard_parameters(sub.tree, links))
    cfg = PassiveConfig(rho_theta=0.0)
    lam, K = np.array(cfg.lam), np.array(cfg.k)
    exact = ContactPassive(base.tables, base.leg, base.gear, (1e9, 1e9), PassiveLaw(run.model, cfg),
                           base.accel)
    robust = ContactPassive(base.tables, base.leg, base.gear, (1e9, 1e9),
                            PassiveLaw(run.model, PassiveConfig(rho_theta=0.5)), base.accel)
    rng = np.random.default_rng(3)
    for k in range(5):
        q, qd = (0.2 + 0.1 * rng.random(), -0.1 + 0.1 * rng.random()), tuple(rng.normal(size=2))
        m = _measurement(0.05 + 0.02 * k, True, q, qd)
        u = np.array(exact.tick(m).torque) * base.gear
        robust.tick(m)  # the same phase (the same measurements)
        assert robust.phase == exact.phase
        ur = np.array(robust.tick(m).torque) * base.gear
        ref = np.array(exact.tables.stance.at(exact.phase)[:4])
        acc = np.array(exact.accel.at(exact.phase))
        e, ed = np.array(q) - ref[:2], np.array(qd) - ref[2:4]
        x = np.r_[q, qd]
        a, v = acc - lam * ed, ref[2:4] - lam * e
        want = np.array(mcg(x, a, v)).ravel() - K * (ed + lam * e)
        np.testing.assert_allclose(u, want, rtol=1e-9, atol=1e-9)
        Yx = np.array(Yf(x, a, v))
        assert np.linalg.norm(ur - u) <= 0.5 * np.linalg.norm(Yx[:, :n_links], 2) + 1e-9
        assert np.abs(Yx[:, n_links:]).max() > 1.0  # the armature's columns: the accelerations


def test_the_baselines_never_emit_a_nan_and_stay_within_the_motors(person) -> None:
    run, _, setup = person
    for name in ("pd", "passive"):
        law = make_baseline(name, run.model, run.gait, run.trajectory, setup)
        lk, la = law.limits
        for m in (_measurement(0.1, True, (2.0, -1.0), (40.0, -30.0)),
                  _measurement(0.2, False, (-1.0, 1.0), (-50.0, 50.0)),
                  ProsthesisMeasurement(0.3, math.nan, 0.0, 0.0, 0.0, 600.0, True, 0.2)):
            u = law.tick(m).torque
            assert np.all(np.isfinite(u)) and abs(u[0]) <= lk and abs(u[1]) <= la, (name, u)


def test_the_reference_accelerations_differentiate_the_rates_without_an_impacts_spike():
    """A stance's rates sampled each ms, with the other heel's strike stepping them by 0.5
    rad/s in one period: the accelerations are the rates' derivative within the central
    difference's error, and the step leaves no spike."""
    t = np.arange(0.0, 0.6, 1e-3)
    w = 2 * np.pi / 0.6
    rates = np.c_[np.sin(w * t), 2 * np.cos(w * t)]
    rates[t >= 0.3] += (0.5, -0.5)
    acc = stance_accelerations(t, rates)
    want = np.c_[w * np.cos(w * t), -2 * w * np.sin(w * t)]
    inner = slice(2, -2)  # the filter's ends
    assert np.abs(acc[inner] - want[inner]).max() < 0.05 * w  # the step's 500 rad/s^2 is gone


def test_pd_walks_the_packaged_persons_gait(person) -> None:
    """10 steps in the in-process plant (AMPRO3's sensors, the torque held each 1 ms within
    the motors) with the paper's frozen PD gains (docs/sweeps.md: passive's do not walk
    it)."""
    run, sim, setup = person
    pd = make_baseline("pd", run.model, run.gait, run.trajectory, setup)
    log = controller_run(sim, run.trajectory, pd, 10)
    assert log.fall is None and log.steps >= 10, log.fall and log.fall.message()


def test_an_unknown_baseline_is_refused(person) -> None:
    run, _, setup = person
    with pytest.raises(ValueError, match="choose pd or passive"):
        make_baseline("clfqp-paper", run.model, run.gait, run.trajectory, setup)
    with pytest.raises(ValueError, match="choose clfqp, phase-pd"):
        make_controller("clfqp-paper", run.model, run.gait, run.trajectory, setup)
    assert make_controller("phase-pd", run.model, run.gait, run.trajectory, setup).name == \
        make_controller("contact-pd", run.model, run.gait, run.trajectory, setup).name
