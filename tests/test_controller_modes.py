"""Domain detection with hysteresis, the shared swing controller (time-based phase), the PD
and robust-passive baselines, and the factory."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from hp_model import bezier
from hp_model.domains import Domain
from hp_model.outputs import phase_rate
from prosthesis_controller import (
    ControllerName,
    ProsthesisMeasurement,
    make_controller,
)
from prosthesis_controller.interface import ControllerMode
from tests.controller_support import tube_about_nominal


def m(t, x=(0.1, 0.1, 0.0, 0.0), load=0.0, contact=False):
    return ProsthesisMeasurement(t, *x, load, contact)


def test_domain_switches_with_hysteresis_and_dwell(ctx):
    cfg = ctx.config.domain
    ctl = make_controller("pd", None, None, None, context=ctx)
    ctl.reset()
    assert ctl.tick(m(0.0)).diagnostics.domain == Domain.PNS  # first sample decides at once
    # stance evidence inside the dwell time is ignored
    assert ctl.tick(m(cfg.min_dwell / 2, load=600, contact=True)).diagnostics.domain == Domain.PNS
    # load between the thresholds with contact: no evidence either way
    assert ctl.tick(m(0.2, load=0.5 * (cfg.load_on + cfg.load_off),
                      contact=True)).diagnostics.domain == Domain.PNS
    out = ctl.tick(m(0.3, load=600, contact=True))
    assert out.diagnostics.domain == Domain.PS and out.diagnostics.mode == ControllerMode.STANCE
    # a contact flicker within the dwell does not end stance
    out = ctl.tick(m(0.3 + cfg.min_dwell / 2, load=0, contact=False))
    assert out.diagnostics.domain == Domain.PS
    # mid-band load keeps stance (hysteresis)
    assert ctl.tick(m(0.5, load=0.5 * (cfg.load_on + cfg.load_off),
                      contact=True)).diagnostics.domain == Domain.PS
    # a one-tick dip of the load below load_off with contact is not a lift-off
    assert ctl.tick(m(0.6, load=10, contact=True)).diagnostics.domain == Domain.PS
    assert ctl.tick(m(0.601, load=600, contact=True)).diagnostics.domain == Domain.PS
    # load held below load_off for off_hold ends stance
    t0 = 0.7
    assert ctl.tick(m(t0, load=10, contact=True)).diagnostics.domain == Domain.PS
    assert ctl.tick(m(t0 + 0.5 * cfg.off_hold, load=10, contact=True)).diagnostics.domain \
        == Domain.PS
    out = ctl.tick(m(t0 + cfg.off_hold, load=10, contact=True))
    assert out.diagnostics.domain == Domain.PNS and out.diagnostics.mode == ControllerMode.SWING
    # losing contact ends stance at once
    ctl.reset()
    ctl.tick(m(0.0, load=600, contact=True))
    assert ctl.tick(m(cfg.min_dwell, load=600, contact=False)).diagnostics.domain == Domain.PNS


def test_swing_tracks_the_pns_rows_with_gravity_at_the_time_based_phase(ctx, model,
                                                                       template_gait):
    """Before the landing starts, at the desired state the swing torque is the gravity
    torque alone; tau_hat is (t - t_liftoff) / T_pns."""
    T = ctx.durations[Domain.PNS]
    pns = template_gait.params[Domain.PNS]
    rows = list(ctx.model.roles[Domain.PNS].prosthesis_rows)
    ctl = make_controller("clfqp", None, None, None, context=ctx)
    ctl.reset()
    t0 = 1.0
    ctl.tick(m(t0))  # lift-off at t0 (first sample: swing)
    sub = ctx.subsystem
    energy = sub.numeric()["energy"]
    pitch_c = ctx.swing_params[2 * (pns.degree + 1):2 * (pns.degree + 1) + 6]
    assert ctx.config.swing.landing_start > 0.6
    for frac in (0.25, 0.6):
        t = t0 + frac * T
        s = frac
        qd = bezier.evaluate(pns.alpha[rows], s)
        vd = bezier.evaluate(bezier.derivative(pns.alpha[rows]), s) / T
        out = ctl.tick(m(t, (*qd, *vd)))
        assert out.diagnostics.tau == pytest.approx(s)
        assert out.diagnostics.mode == ControllerMode.SWING
        # gravity torque = dPE/dq at the nominal socket pitch (finite differences of the
        # subsystem's energy function: an independent path to the same model)
        q = np.r_[0.0, 0.0, float(bezier.evaluate(pitch_c[None, :], s)[0]), qd]
        g = np.zeros(2)
        for j in range(2):
            e = np.zeros(5)
            e[3 + j] = 1e-6
            vp = float(energy(q + e, np.zeros(5))[1][0])  # copy: buffers are reused
            vm = float(energy(q - e, np.zeros(5))[1][0])
            g[j] = (vp - vm) / 2e-6
        np.testing.assert_allclose(out.torque * np.array(ctx.gear), g, rtol=1e-6, atol=1e-6)


@pytest.fixture(scope="module")
def stored_ctx(model, subsystem, playback_gait):
    """A context on the stored human-like gait (ps 0.81 s; tests/data/playback)."""
    from prosthesis_controller import ControllerContext

    gait = playback_gait
    return ControllerContext(gait, tube_about_nominal(gait, (40, 60, 8)), model,
                             subsystem=subsystem)


def test_swing_landing_straightens_the_shank_and_flattens_the_foot(stored_ctx):
    """From landing_start on, the swing target turns the shank toward the vertical under the
    knee by the fraction w of its angle (w = reach (s - start) / (1 - start), capped at 1)
    and the foot flat in the world (socket at its nominal pitch), which lowers the sole;
    checked with the subsystem's forward kinematics (the 5-DOF tree's frames, not the
    controller's terms)."""
    ctx = stored_ctx
    sw = ctx.config.swing
    T = ctx.durations[Domain.PNS]
    pns = ctx.gait.params[Domain.PNS]
    rows = list(ctx.model.roles[Domain.PNS].prosthesis_rows)
    pitch_c = ctx.swing_params[2 * (pns.degree + 1):2 * (pns.degree + 1) + 6]
    f = ctx.terms.numeric["swing_ref"]
    frames = ctx.subsystem.numeric()["frames"]
    idx = {n: ctx.subsystem.frame_index(n) for n in ("p_knee", "p_ankle", "p_sole")}

    def geometry(pitch, qj):
        P = frames(np.r_[0.0, 0.0, pitch, qj], np.zeros(5))[0]
        k, a, s = P[:, idx["p_knee"]], P[:, idx["p_ankle"]], P[:, idx["p_sole"]]
        return np.arctan2(a[0] - k[0], k[1] - a[1]), s[1], s[2]  # psi, sole z, foot pitch

    dev = ctx.model.device.prosthesis
    L, h = dev.shin.length.value, dev.foot.ankle_height.value
    a, flat = sw.landing_start, sw.landing_start + sw.landing_flatten
    for s_raw in (0.5 * (a + flat), flat + 0.02, 1.0, 1.3, 12.0):
        s = min(s_raw, 1.0)
        q_d = f(np.zeros(4), s_raw, 1.0 / T, ctx.swing_params)[0].copy()
        pitch = float(bezier.evaluate(pitch_c[None, :], s)[0])
        psi0, z0, foot0 = geometry(pitch, bezier.evaluate(pns.alpha[rows], s))
        psi, z, foot = geometry(pitch, q_d)
        w = min(sw.landing_reach * (s_raw - a) / (1 - a), 1.0)
        w_flat = min((s_raw - a) / sw.landing_flatten, 1.0)
        assert psi == pytest.approx((1 - w) * psi0, abs=1e-9)
        assert foot == pytest.approx((1 - w_flat) * foot0, abs=1e-9)
        # the knee stays put: sole z = z_knee - L_shin cos(psi) - h_ankle cos(foot pitch)
        dz = L * (np.cos(psi) - np.cos(psi0)) + h * (np.cos(foot) - np.cos(foot0))
        assert z == pytest.approx(z0 - dz, abs=1e-9)
        if w > 0:
            assert z < z0
    # before landing_start the target is the Bezier posture
    q_d = f(np.zeros(4), 0.5 * a, 1.0 / T, ctx.swing_params)[0].copy()
    np.testing.assert_allclose(q_d, bezier.evaluate(pns.alpha[rows], 0.5 * a), atol=1e-12)


def test_phase_pd_is_feedforward_on_the_nominal_plus_pd_and_hip_velocity(ctx, template_gait):
    """On the nominal (y = 0) the phase-PD torque is the fitted nominal stance torque; a
    knee error adds -kp y2 - kd dy2 and a hip-velocity error k_vhip y1 (joint side); the
    feedforward fit reproduces the gait's collocation torques."""
    ps = template_gait.params[Domain.PS]
    hip = ctx.terms.hip
    ck, ca_ = hip.c_knee, hip.c_ankle
    cfg = ctx.config.phase_pd
    gear = np.array(ctx.gear)
    ctl = make_controller("phase-pd", None, None, None, context=ctx)
    ctl.reset()
    ctl.tick(m(0.0, load=600, contact=True))
    ff = template_gait.controller_curves.stance_torque
    tr = template_gait.trajectory[Domain.PS]
    q, u = np.asarray(tr["q"]), np.asarray(tr["u"])
    tau_c = hip.phase(q[10], q[11], ps.p_min, ps.p_max)
    fit = bezier.evaluate(ff, np.clip(tau_c, 0, 1))
    # fit error well below the motor limits (2.4, 3 N m): 5 % of them
    assert np.abs(fit - u[4:6].T).max() < 0.05 * min(ctx.limits)
    for k, tau in enumerate((0.2, 0.5, 0.8)):
        qk = float(bezier.evaluate(ps.alpha[4:5], tau)[0])
        qa = hip.ankle(ps.delta_p_at(tau), qk)
        # velocities on the nominal: tau_dot at v_hip, knee dB/dtau tau_dot
        vk = float(bezier.evaluate(bezier.derivative(ps.alpha[4:5]), tau)[0]) * ps.nominal_rate
        va = hip.ankle(ps.v_hip, vk)
        t = 0.1 + 0.1 * k
        out = ctl.tick(m(t, (qk, qa, vk, va), load=600, contact=True))
        expected = bezier.evaluate(ff, tau)
        np.testing.assert_allclose(out.torque, expected, atol=1e-9)
        assert out.diagnostics.tau == pytest.approx(tau, abs=1e-12)
        # knee error e (tau unchanged: the ankle moves by -c_k/c_a e) and hip speed error dv
        e, dv = 0.01, 0.05
        out = ctl.tick(m(t + 0.01, (qk + e, qa - ck / ca_ * e, vk, va + dv / ca_),
                         load=600, contact=True))
        # y2 = e; dy2 = -dB/dtau * dv / dp (tau_dot grows with the hip speed); y1 = dv
        dB = float(bezier.evaluate(bezier.derivative(ps.alpha[4:5]), tau)[0])
        dy2 = -dB * phase_rate(dv, ps.p_min, ps.p_max)
        fb = np.array([-cfg.kp * e - cfg.kd * dy2, cfg.k_vhip * dv]) / gear
        np.testing.assert_allclose(out.torque, expected + fb, atol=1e-9)


def test_pd_reference_obeys_the_phase_relation_and_vanishes_on_it(ctx, template_gait):
    """PD tracks the nominal trajectory as a function of the state-based phase tau(q) (the
    paper's trajectories are), its velocities at the nominal phase rate v_hip* / dp: zero
    torque on it; off it, kp (q_d(tau(q)) - q) + kd (v_d - v), where q_d(tau(q)) - q has the
    ankle error -(c_k / c_a) times the knee's (the phase pins delta_p_hip)."""
    ps = template_gait.params[Domain.PS]
    hip = ctx.terms.hip
    rate = ps.nominal_rate
    f = ctx.terms.numeric["stance_ref"]
    ctl = make_controller("pd", None, None, None, context=ctx)
    ctl.reset()
    t0 = 2.0
    ctl.tick(m(t0, load=600, contact=True))  # heel strike at t0
    kp, kd = np.array(ctx.config.pd.kp), np.array(ctx.config.pd.kd)
    for k, frac in enumerate((0.1, 0.5, 0.9)):
        q_d, v_d, _ = (a.copy() for a in f(frac, rate, ctx.stance_params))
        # delta_p_hip(q_d) is the phase's
        assert hip(q_d[0], q_d[1]) == pytest.approx(ps.delta_p_at(frac), abs=1e-12)
        out = ctl.tick(m(t0 + 0.01 * (2 * k + 1), (*q_d, *v_d), load=600, contact=True))
        np.testing.assert_allclose(out.torque, 0.0, atol=1e-9)
        q = q_d + np.array([0.01, -0.02])
        v = v_d + np.array([0.3, 0.1])
        tau = hip.phase(q[0], q[1], ps.p_min, ps.p_max)
        q_r, v_r, _ = (a.copy() for a in f(tau, rate, ctx.stance_params))
        e = q_r - q
        assert e[1] == pytest.approx(-(hip.c_knee / hip.c_ankle) * e[0], rel=1e-9)
        out = ctl.tick(m(t0 + 0.01 * (2 * k + 2), (*q, *v), load=600, contact=True))
        expected = (kp * e + kd * (v_r - v)) / np.array(ctx.gear)
        lim = np.array(ctx.limits)
        np.testing.assert_allclose(out.torque, np.clip(expected, -lim, lim), rtol=1e-9)


def test_passive_on_the_reference_is_inverse_dynamics_without_socket_force(ctx, template_gait):
    """On the reference at the state-based phase (e = 0, e_dot = 0): r = 0, the robust term
    vanishes, u = M qdd_d + C qd_d + g."""
    ps = template_gait.params[Domain.PS]
    rate = ps.nominal_rate
    f = ctx.terms.numeric["stance_ref"]
    lag = ctx.terms.numeric["lagrangian"]
    ctl = make_controller("passive", None, None, None, context=ctx)
    ctl.reset()
    t0 = 3.0
    ctl.tick(m(t0, load=600, contact=True))
    for k, frac in enumerate((0.2, 0.7)):
        q_d, v_d, a_d = (a.copy() for a in f(frac, rate, ctx.stance_params))
        out = ctl.tick(m(t0 + 0.01 * (k + 1), (*q_d, *v_d), load=600, contact=True))
        M, g, Cqd = (a.copy() for a in lag(np.r_[q_d, v_d]))
        expected = (M @ a_d + Cqd + g) / np.array(ctx.gear)
        lim = np.array(ctx.limits)
        np.testing.assert_allclose(out.torque, np.clip(expected, -lim, lim), rtol=1e-9,
                                   atol=1e-12)


def test_factory_refuses_unknown_names_and_foreign_tubes(model, subsystem, template_gait, ctx):
    with pytest.raises(ValueError, match="unknown controller"):
        make_controller("lqr", None, None, None, context=ctx)
    foreign = dataclasses.replace(tube_about_nominal(template_gait, (1, 1, 1)),
                                  gait_hash="0" * 16)
    with pytest.raises(ValueError, match="tube was made for gait"):
        make_controller("clfqp", template_gait, foreign, model, subsystem=subsystem)
    for name in ControllerName:
        assert make_controller(name, None, None, None, context=ctx).name == name
