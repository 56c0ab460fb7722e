"""The mocap stage's low-pass, gap filling and rigid-body pitch (scipy's Butterworth design
and ``sosfiltfilt``, ``CubicSpline`` and ``Rotation``): each finite run filtered on its own
(NaN runs kept) with the gain a zero-phase order-2 Butterworth has at the take's rate; short
gaps filled by the not-a-knot spline through the samples around them; a rigid body's sagittal
pitch from its quaternion; and no low-pass above a take's Nyquist frequency."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import signal
from scipy.interpolate import CubicSpline

from characterization.mocap.foot_contact import ContactOptions, foot_contact
from characterization.mocap.limb_angles import fill_short_gaps, lowpass
from characterization.mocap.sagittal import SagittalFrame, axis_vector

RATE = 120.0  # Hz, the synthetic subject's and a Motive take's usual rate
CUTOFF = 15.0  # Hz, the mapping's default processing.lowpass_hz


def test_lowpass_keeps_nan_runs_and_filters_each_finite_run() -> None:
    t = np.arange(600) / RATE
    y = np.sin(2 * np.pi * 1.3 * t) + 0.05 * np.random.default_rng(0).normal(size=600)
    y[200:230] = np.nan
    out = lowpass(y, RATE, 6.0)
    assert np.isnan(out[200:230]).all()
    sos = signal.butter(2, 6.0 / 60.0, output="sos")
    np.testing.assert_array_equal(out[:200], signal.sosfiltfilt(sos, y[:200]))
    np.testing.assert_array_equal(out[230:], signal.sosfiltfilt(sos, y[230:]))


def _gain(f_hz: float) -> float:
    """Amplitude of ``lowpass`` (default cutoff, 120 Hz) on a unit sine of ``f_hz`` over
    10 s, measured away from the ends."""
    t = np.arange(1200) / RATE
    out = lowpass(np.sin(2 * np.pi * f_hz * t), RATE, CUTOFF)[300:-300]
    return float(np.sqrt(2 * np.mean(out ** 2)))


def test_lowpass_passes_gait_and_removes_what_is_above_the_cutoff() -> None:
    """Order 2 forwards and backwards: the Butterworth gain squared, 1 / (1 + (f / fc)^4)
    before the bilinear warping; 1/2 at the cutoff.  The stride's harmonics up to 3 Hz pass
    within 0.2 %, 6 Hz within 3 %; 30 Hz marker jitter is cut to 3 %, 40 Hz to 0.4 %."""
    assert _gain(1.0) == pytest.approx(1.0, abs=1e-4)
    assert _gain(3.0) == pytest.approx(1.0, abs=2e-3)
    assert _gain(6.0) == pytest.approx(1.0, abs=0.03)
    assert _gain(CUTOFF) == pytest.approx(0.5, abs=1e-6)
    assert _gain(30.0) < 0.03
    assert _gain(40.0) < 0.004


def test_lowpass_leaves_short_runs_and_a_zero_cutoff_alone() -> None:
    """A run no longer than sosfiltfilt's padding (9 samples at order 2) stays as sampled,
    a longer one is filtered; a cutoff of 0 is the mapping's "off"."""
    rng = np.random.default_rng(1)
    y = rng.normal(size=30)
    y[9] = y[20] = np.nan  # runs of 9 (kept), 10 (filtered) and 9 samples (kept)
    out = lowpass(y, RATE, CUTOFF)
    np.testing.assert_array_equal(out[:10], y[:10])
    np.testing.assert_array_equal(out[20:], y[20:])
    assert np.all(np.abs(out[10:20] - y[10:20]) > 0)
    assert lowpass(y, RATE, 0.0) is y


@pytest.mark.parametrize("n_ok", [2, 3, 4, 50])
def test_gap_fill_is_the_spline_through_the_samples(n_ok: int) -> None:
    t = np.arange(n_ok + 3) / 100.0
    y = np.cos(3 * t)
    y[1:4] = np.nan  # one gap of 3 frames with samples on both sides
    filled, mask, gaps = fill_short_gaps(t, y, 5)
    ok = np.isfinite(y)
    np.testing.assert_array_equal(filled[1:4], CubicSpline(t[ok], y[ok])(t[1:4]))
    assert mask[1:4].all() and gaps == [(1, 4)]


def test_gap_fill_reproduces_a_cubic_and_leaves_long_and_edge_gaps() -> None:
    """The not-a-knot spline through samples of a cubic is that cubic; a gap longer than
    ``max_gap`` or touching either end of the take stays NaN."""
    t = np.arange(200) / RATE
    cubic = 0.3 - 1.2 * t + 2.5 * t ** 2 - 4.0 * t ** 3
    y = cubic.copy()
    y[:3] = y[40:48] = y[100:130] = y[-2:] = np.nan
    filled, mask, gaps = fill_short_gaps(t, y, 12)
    np.testing.assert_allclose(filled[40:48], cubic[40:48], rtol=0, atol=1e-12)
    assert mask.sum() == 8 and mask[40:48].all()
    for a, b in ((0, 3), (100, 130), (198, 200)):
        assert np.isnan(filled[a:b]).all()
    assert gaps == [(0, 3), (40, 48), (100, 130), (198, 200)]


def test_rigid_body_pitch_from_a_known_quaternion() -> None:
    """Y-up lab walking along +X: the walker's left is lab -Z, so a pitch of +theta is a
    rotation by -theta about lab +Z, q = (0, 0, sin(-theta/2), cos(-theta/2)).  Both body
    axes give theta; the quaternion need not be unit; a NaN quaternion gives NaN."""
    f = SagittalFrame(forward=axis_vector("+x"), up=axis_vector("+y"))
    np.testing.assert_allclose(f.lateral, [0, 0, -1])
    theta = np.array([-0.9, -0.2, 0.0, 0.3, 1.4])
    q = np.column_stack([0 * theta, 0 * theta, np.sin(-theta / 2), np.cos(-theta / 2)])
    q = np.vstack([q * 2.5, np.full(4, np.nan)])
    for axis in ("up", "forward"):
        got = f.pitch_from_quaternion(q, axis)
        np.testing.assert_allclose(got[:-1], theta, rtol=0, atol=1e-12)
        assert np.isnan(got[-1])


@pytest.mark.parametrize("rate", [20.0, 16.0])
def test_a_take_at_or_below_twice_the_contact_cutoff_does_not_raise(rate: float) -> None:
    """Foot contact's 10 Hz low-pass at a take of 20 Hz or less sits at or above Nyquist,
    where the Butterworth design has no filter (ValueError): the contact stage skips it."""
    with pytest.raises(ValueError):
        lowpass(np.zeros(100), rate, rate / 2)
    t = np.arange(0, 6.0, 1 / rate)
    phase = (t / 1.2) % 1.0
    stance = phase < 0.6
    x = np.cumsum(np.where(stance, 0.0, 1.3 / rate))
    z = np.where(stance, 0.0, 0.08 * np.sin(np.pi * (phase - 0.6) / 0.4))
    fc = foot_contact(np.column_stack([x, z + 0.05]), np.column_stack([x + 0.2, z + 0.03]), t,
                      ContactOptions(cutoff_hz=10.0))
    assert fc.contact[stance].mean() > 0.8 and fc.contact[~stance].mean() < 0.3
