"""The swing's thigh lead: the socket IMU's pitch advances the swing phase when the human's
thigh is ahead of the nominal swing (prosthesis_controller.config.SwingConfig)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from hp_model import bezier
from hp_model.domains import Domain
from prosthesis_controller import ControllerContext, ProsthesisMeasurement, make_controller
from prosthesis_controller.config import ControllerConfig, SwingConfig
from prosthesis_controller.context import thigh_phase_table
from prosthesis_controller.measurement import Fault, validate
from tests.controller_support import tube_about_nominal


def test_pitch_row_is_the_socket_frames_world_pitch(model):
    """c . q equals the socket frame's pitch from the model's forward kinematics, and it is
    what the IMU on the prosthesis top link sees: base pitch + hip + socket joint."""
    c = model.pitch_row("socket")
    frames = model.numeric()["frames"]
    i = model.frame_index("socket")
    rng = np.random.default_rng(3)
    for _ in range(5):
        q = rng.uniform(-1.0, 1.0, model.nq)
        assert float(c @ q) == pytest.approx(float(frames(q, np.zeros(model.nq))[0][2, i]),
                                             abs=1e-12)
    assert set(np.flatnonzero(c)) == {model.coord_names.index(n)
                                      for n in ("th_B", "th_rh", "th_f")}


def test_thigh_phase_table_takes_the_falling_branch_inside_the_window():
    s = np.linspace(0.0, 1.0, 201)
    # a pitch that rises to s = 0.3 and then falls: the branch is [0.3, 0.65]
    fall = np.polynomial.polynomial.polyfit(s, -((s - 0.3) ** 2), 4)
    coef = np.linalg.lstsq(bezier.basis(5, s), np.polynomial.polynomial.polyval(s, fall),
                           rcond=None)[0]
    tab = thigh_phase_table(coef, (0.2, 0.65))
    assert tab is not None
    p, ph = tab
    assert np.all(np.diff(p) > 0) and np.all(np.diff(ph) < 0)  # for np.interp, invertible
    assert ph[-1] == pytest.approx(0.3, abs=0.01) and ph[0] == pytest.approx(0.65, abs=0.01)
    # a rising pitch has no branch; one that falls over less than min_span has none either
    assert thigh_phase_table(np.linspace(0.0, 1.0, 6), (0.2, 0.65)) is None
    assert thigh_phase_table(coef, (0.2, 0.65), min_span=0.4) is None
    # min_slope keeps the steep part: |slope| = 2 (s - 0.3) >= 0.5 * 0.7 from s = 0.475
    _p2, ph2 = thigh_phase_table(coef, (0.2, 0.65), min_slope=0.5, min_span=0.1)
    assert ph2[-1] == pytest.approx(0.475, abs=0.01) and ph2[0] == pytest.approx(0.65, abs=0.01)
    assert thigh_phase_table(coef, (0.2, 0.65), min_slope=0.5, min_span=0.2) is None


@pytest.fixture(scope="module")
def lead_ctx(model, subsystem, playback_gait):
    gait = playback_gait
    return ControllerContext(gait, tube_about_nominal(gait, (40, 60, 8)), model,
                             subsystem=subsystem)


def _swing_tau(ctl, ctx, t0, T, frac, pitch):
    """tau reported by one swing tick at t0 + frac T with the knee/ankle on the nominal."""
    q = bezier.evaluate(_rows(ctx), frac)
    out = ctl.tick(ProsthesisMeasurement(t0 + frac * T, float(q[0]), float(q[1]), 0.0, 0.0,
                                         0.0, False, pitch))
    return float(out.diagnostics.tau)


def _rows(ctx):

    idx = [Domain.PNS.y2_coords.index(c) for c in ("th_pk", "th_pa")]
    return ctx.gait.params[Domain.PNS].alpha[idx]


def test_a_thigh_ahead_of_the_nominal_advances_the_swing_low_pass_filtered(lead_ctx, model):
    """With the IMU reading the nominal pitch of phase s + d while the clock says s, the
    reported phase approaches s + d as a first-order filter with the configured time
    constant; it is held after the branch and reset at the next lift-off."""
    ctx = lead_ctx
    assert ctx.thigh_table is not None
    T = ctx.durations[Domain.PNS]
    tc = ctx.config.swing.lead_time_constant
    pitch_c = ctx.gait.controller_curves.socket_pitch
    p_at = lambda s: float(bezier.evaluate(pitch_c, s)[0])  # noqa: E731
    ctl = make_controller("clfqp", None, None, None, context=ctx)
    ctl.reset()
    t0, d, dt = 1.0, 0.05, 1e-3
    s_lo, s_hi = float(ctx.thigh_table[1][-1]), float(ctx.thigh_table[1][0])
    ctl.tick(ProsthesisMeasurement(t0, 0.1, 0.1, 0.0, 0.0, 0.0, False, p_at(d)))  # lift-off
    lead, started = 0.0, False
    for k in range(1, math.ceil((s_hi - d - 0.01) * T / dt)):  # s + d on the branch
        s = k * dt / T
        tau = _swing_tau(ctl, ctx, t0, T, s, p_at(s + d))
        if s < s_lo:  # before the branch: the clock alone, whatever the pitch
            assert tau == pytest.approx(s, abs=1e-12)
            continue
        lead += min(dt / tc, 1.0) * (d - lead) if started else 0.0
        started = True
        # the inverse of the 5th-degree pitch on a 401-point table: 1e-3 in phase
        assert tau == pytest.approx(s + lead, abs=2e-3)
    assert lead > 0.95 * d  # settled: several time constants
    # after the branch the lead is held; at the next lift-off it is gone
    s = min(s_hi + 0.1, 0.79)
    assert _swing_tau(ctl, ctx, t0, T, s, math.nan) == pytest.approx(s + lead, abs=2e-3)
    ctl.tick(ProsthesisMeasurement(t0 + T, 0.1, 0.1, 0.0, 0.0, 600.0, True, p_at(0.0)))
    t1 = t0 + T + 0.5
    ctl.tick(ProsthesisMeasurement(t1, 0.1, 0.1, 0.0, 0.0, 0.0, False, p_at(0.0)))
    assert _swing_tau(ctl, ctx, t1, T, 0.5 * s_lo, math.nan) \
        == pytest.approx(0.5 * s_lo, abs=1e-12)


@pytest.mark.parametrize("offset", [-0.05, math.nan])
def test_a_late_thigh_or_no_imu_leaves_the_clock(lead_ctx, model, offset):
    """The lead never retards the swing; without a pitch (NaN) the phase is the clock."""
    ctx = lead_ctx
    T = ctx.durations[Domain.PNS]
    pitch_c = ctx.gait.controller_curves.socket_pitch
    ctl = make_controller("clfqp", None, None, None, context=ctx)
    ctl.reset()
    t0 = 2.0
    ctl.tick(ProsthesisMeasurement(t0, 0.1, 0.1, 0.0, 0.0, 0.0, False))
    for s in np.arange(0.05, 0.75, 0.01):
        p = float(bezier.evaluate(pitch_c, s + offset)[0]) if math.isfinite(offset) \
            else math.nan
        assert _swing_tau(ctl, ctx, t0, T, float(s), p) == pytest.approx(s, abs=1e-12)


def test_without_thigh_lead_the_pitch_is_ignored(model, subsystem, playback_gait):
    ctx = ControllerContext(playback_gait, tube_about_nominal(playback_gait, (40, 60, 8)),
                            model, ControllerConfig(swing=SwingConfig(thigh_lead=False)),
                            subsystem=subsystem)
    assert ctx.thigh_table is None
    T = ctx.durations[Domain.PNS]
    ctl = make_controller("clfqp", None, None, None, context=ctx)
    ctl.reset()
    ctl.tick(ProsthesisMeasurement(0.0, 0.1, 0.1, 0.0, 0.0, 0.0, False, 0.3))
    pitch_c = playback_gait.controller_curves.socket_pitch
    for s in np.arange(0.2, 0.6, 0.01):
        p = float(bezier.evaluate(pitch_c, s + 0.1)[0])
        assert _swing_tau(ctl, ctx, 0.0, T, float(s), p) == pytest.approx(s, abs=1e-12)


def test_the_deadband_is_taken_off_the_lead(model, subsystem, playback_gait):
    """``lead_deadband`` d0: the phase advances by max(lead - d0, 0) (an IMU bias below
    d0 times the pitch slope moves nothing)."""
    ctx = ControllerContext(playback_gait, tube_about_nominal(playback_gait, (40, 60, 8)),
                            model, ControllerConfig(swing=SwingConfig(lead_deadband=0.03)),
                            subsystem=subsystem)
    T = ctx.durations[Domain.PNS]
    pitch_c = playback_gait.controller_curves.socket_pitch
    s_hi = float(ctx.thigh_table[1][0])
    for d, expect in ((0.02, 0.0), (0.06, 0.03)):
        ctl = make_controller("clfqp", None, None, None, context=ctx)
        ctl.reset()
        ctl.tick(ProsthesisMeasurement(0.0, 0.1, 0.1, 0.0, 0.0, 0.0, False))
        for k in range(1, math.ceil((s_hi - d) * T / 1e-3)):
            s = k * 1e-3 / T
            tau = _swing_tau(ctl, ctx, 0.0, T, s, float(bezier.evaluate(pitch_c, s + d)[0]))
        # settled while s + d is on the branch (> 3 time constants: e^-3 of the lead left)
        assert tau == pytest.approx(s + expect, abs=2.5e-3)


def test_lead_window_is_validated():
    with pytest.raises(ValueError, match="lead_window"):
        SwingConfig(lead_window=(0.6, 0.3))


def test_socket_pitch_validation():
    base = dict(t=1.0, knee_angle=0.1, ankle_angle=0.0, knee_vel=0.0, ankle_vel=0.0)
    rng = ((-0.5, 2.5), (-1.0, 1.0), 50.0, (0.0, 2000.0))
    assert validate(ProsthesisMeasurement(**base, socket_pitch=math.nan), 0.0, *rng) \
        == Fault.NONE
    assert validate(ProsthesisMeasurement(**base, socket_pitch=0.2), 0.0, *rng) == Fault.NONE
    assert validate(ProsthesisMeasurement(**base, socket_pitch=math.inf), 0.0, *rng) \
        == Fault.NON_FINITE
