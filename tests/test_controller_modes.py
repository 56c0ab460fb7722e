"""Domain detection with hysteresis, the shared swing controller (time-based phase), the PD
and robust-passive baselines, and the factory."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from hp_model import bezier
from hp_model.outputs import Y2_COORDS
from prosthesis_controller import (
    CONTROLLERS,
    ProsthesisMeasurement,
    make_controller,
)
from prosthesis_controller.interface import MODE_STANCE, MODE_SWING
from tests.controller_support import tube_about_nominal


def m(t, x=(0.1, 0.1, 0.0, 0.0), load=0.0, contact=False):
    return ProsthesisMeasurement(t, *x, load, contact)


def test_domain_switches_with_hysteresis_and_dwell(ctx):
    cfg = ctx.config.domain
    ctl = make_controller("pd", None, None, None, context=ctx)
    ctl.reset()
    assert ctl.tick(m(0.0)).diagnostics.domain == "pns"  # first sample decides at once
    # stance evidence inside the dwell time is ignored
    assert ctl.tick(m(cfg.min_dwell / 2, load=600, contact=True)).diagnostics.domain == "pns"
    # load between the thresholds with contact: no evidence either way
    assert ctl.tick(m(0.2, load=0.5 * (cfg.load_on + cfg.load_off),
                      contact=True)).diagnostics.domain == "pns"
    out = ctl.tick(m(0.3, load=600, contact=True))
    assert out.diagnostics.domain == "ps" and out.diagnostics.mode == MODE_STANCE
    # a contact flicker within the dwell does not end stance
    assert ctl.tick(m(0.3 + cfg.min_dwell / 2, load=0, contact=False)).diagnostics.domain == "ps"
    # mid-band load keeps stance (hysteresis)
    assert ctl.tick(m(0.5, load=0.5 * (cfg.load_on + cfg.load_off),
                      contact=True)).diagnostics.domain == "ps"
    out = ctl.tick(m(0.6, load=10, contact=True))  # load below load_off ends stance
    assert out.diagnostics.domain == "pns" and out.diagnostics.mode == MODE_SWING


def test_swing_tracks_the_pns_rows_with_gravity_at_the_time_based_phase(ctx, model,
                                                                       template_gait):
    """At the desired state the swing torque is the gravity torque alone; tau_hat is
    (t - t_liftoff) / T_pns, clipped to [0, 1]."""
    T = ctx.durations["pns"]
    pns = template_gait.params["pns"]
    rows = [Y2_COORDS["pns"].index(c) for c in ("th_pk", "th_pa")]
    ctl = make_controller("clfqp", None, None, None, context=ctx)
    ctl.reset()
    t0 = 1.0
    ctl.tick(m(t0))  # lift-off at t0 (first sample: swing)
    sub = ctx.subsystem
    energy = sub.numeric()["energy"]
    pitch_c = ctx.swing_params[-(ctx.terms.swing_layout.size - 2 * (pns.degree + 1)):]
    for frac in (0.25, 0.6, 1.4):
        t = t0 + frac * T
        s = min(frac, 1.0)
        qd = bezier.evaluate(pns.alpha[rows], s)
        vd = bezier.evaluate(bezier.derivative(pns.alpha[rows]), s) / T if frac < 1 else 0 * qd
        out = ctl.tick(m(t, (*qd, *vd)))
        assert out.diagnostics.tau == pytest.approx(s)
        assert out.diagnostics.mode == MODE_SWING
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


def test_pd_reference_obeys_the_phase_relation_and_vanishes_on_it(ctx, template_gait):
    ps = template_gait.params["ps"]
    ck, ca_ = ctx.terms.c_k, ctx.terms.c_a
    f = ctx.terms.numeric["stance_ref"]
    T = ctx.durations["ps"]
    ctl = make_controller("pd", None, None, None, context=ctx)
    ctl.reset()
    t0 = 2.0
    ctl.tick(m(t0, load=600, contact=True))  # heel strike at t0
    for frac in (0.1, 0.5, 0.9):
        q_d, v_d, _ = (a.copy() for a in f(frac, 1.0 / T, ctx.stance_params))
        # delta_p_hip(q_d) = p_min + tau (p_max - p_min)
        assert ck * q_d[0] + ca_ * q_d[1] == pytest.approx(
            ps.p_min + frac * (ps.p_max - ps.p_min), abs=1e-12)
        out = ctl.tick(m(t0 + frac * T, (*q_d, *v_d), load=600, contact=True))
        np.testing.assert_allclose(out.torque, 0.0, atol=1e-9)
        # an error produces a restoring torque with the PD gains
        e = np.array([0.01, -0.02])
        t1 = t0 + frac * T + 1e-3
        q1, v1, _ = (a.copy() for a in f((t1 - t0) / T, 1.0 / T, ctx.stance_params))
        out = ctl.tick(m(t1, (*(q1 + e), *v1), load=600, contact=True))
        kp = np.array(ctx.config.pd.kp)
        np.testing.assert_allclose(out.torque, -kp * e / np.array(ctx.gear), rtol=1e-9)


def test_passive_on_the_reference_is_inverse_dynamics_without_socket_force(ctx):
    """e = 0, e_dot = 0: r = 0, the robust term vanishes, u = M qdd_d + C qd_d + g."""
    f = ctx.terms.numeric["stance_ref"]
    lag = ctx.terms.numeric["lagrangian"]
    T = ctx.durations["ps"]
    ctl = make_controller("passive", None, None, None, context=ctx)
    ctl.reset()
    t0 = 3.0
    ctl.tick(m(t0, load=600, contact=True))
    for frac in (0.2, 0.7):
        q_d, v_d, a_d = (a.copy() for a in f(frac, 1.0 / T, ctx.stance_params))
        out = ctl.tick(m(t0 + frac * T, (*q_d, *v_d), load=600, contact=True))
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
    for name in CONTROLLERS:
        assert make_controller(name, None, None, None, context=ctx).name == name
