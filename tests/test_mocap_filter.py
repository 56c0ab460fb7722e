"""The mocap stage's low-pass and gap filling: each finite run filtered on its own (NaN runs
kept), short gaps filled by the spline through the samples around them."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import signal
from scipy.interpolate import CubicSpline

from characterization.mocap import butterworth
from characterization.mocap.limb_angles import fill_short_gaps, lowpass


def test_lowpass_keeps_nan_runs_and_filters_each_finite_run() -> None:
    t = np.arange(600) / 120.0
    y = np.sin(2 * np.pi * 1.3 * t) + 0.05 * np.random.default_rng(0).normal(size=600)
    y[200:230] = np.nan
    out = lowpass(y, 120.0, 6.0)
    assert np.isnan(out[200:230]).all()
    sos = signal.butter(2, 6.0 / 60.0, output="sos")
    # scipy.signal as the reference (the filter's own: butterworth.py)
    np.testing.assert_array_equal(out[:200], signal.sosfiltfilt(sos, y[:200]))
    np.testing.assert_array_equal(out[230:], signal.sosfiltfilt(sos, y[230:]))


@pytest.mark.parametrize("order", range(1, 9))
def test_butterworth_is_scipy_signals(order: int) -> None:
    """The design and the zero-phase filtering of butterworth.py against scipy.signal (not
    imported by the pipeline, for its import time): the same transfer function to rounding,
    -3 dB at the cutoff, and the same filtered signal (1e-12 of its magnitude) over cutoffs
    from 1 % to 99 % of Nyquist and signals from just past the padding to 5000 samples."""
    rng = np.random.default_rng(order)
    for wn in (0.01, 0.05, 0.1, 0.25, 0.5, 0.9, 0.99):
        ours, ref = butterworth.butter_lowpass_sos(order, wn), signal.butter(order, wn,
                                                                           output="sos")
        assert ours.shape == ref.shape
        for a, b in zip(signal.sos2tf(ours), signal.sos2tf(ref), strict=True):
            np.testing.assert_allclose(a, b, rtol=0, atol=1e-14 * np.abs(b).max())
        _, h = signal.sosfreqz(ours, worN=[np.pi * wn])
        assert abs(h[0]) == pytest.approx(2 ** -0.5, rel=1e-9)
        for n in (butterworth.pad_length(ours) + 1, 500, 5000):
            x = np.cumsum(rng.standard_normal(n))
            want = signal.sosfiltfilt(ref, x)
            np.testing.assert_allclose(butterworth.sosfiltfilt(ours, x), want, rtol=0,
                                       atol=1e-12 * np.abs(x).max())


@pytest.mark.parametrize("wn", [0.01, 0.06, 0.1, 0.12, 0.15, 1 / 6, 0.25, 0.3, 0.33, 0.77, 0.9])
def test_butterworth_of_order_2_is_scipy_signals_bit_for_bit(wn: float) -> None:
    """The pipeline's order: the sections, initial conditions and filtered signal equal
    scipy.signal's exactly (the gait fits downstream amplify a last-bit difference in the
    steps to 2e-4 rad: tests/test_committed_gaits.py)."""
    ours, ref = butterworth.butter_lowpass_sos(2, wn), signal.butter(2, wn, output="sos")
    np.testing.assert_array_equal(ours, ref)
    np.testing.assert_array_equal(butterworth.sosfilt_zi(ours), signal.sosfilt_zi(ref))
    x = np.cumsum(np.random.default_rng(7).standard_normal(3000))
    np.testing.assert_array_equal(butterworth.sosfiltfilt(ours, x), signal.sosfiltfilt(ref, x))


def test_butterworth_refuses_what_it_cannot_filter() -> None:
    with pytest.raises(ValueError, match="order 0"):
        butterworth.butter_lowpass_sos(0, 0.1)
    with pytest.raises(ValueError, match=r"cutoff 1\.0"):
        butterworth.butter_lowpass_sos(2, 1.0)
    sos = butterworth.butter_lowpass_sos(2, 0.1)
    with pytest.raises(ValueError, match="longer than 9 samples"):
        butterworth.sosfiltfilt(sos, np.zeros(9))


@pytest.mark.parametrize("n_ok", [2, 3, 4, 50])
def test_gap_fill_is_the_spline_through_the_samples(n_ok: int) -> None:
    t = np.arange(n_ok + 3) / 100.0
    y = np.cos(3 * t)
    y[1:4] = np.nan  # one gap of 3 frames with samples on both sides
    filled, mask, gaps = fill_short_gaps(t, y, 5)
    ok = np.isfinite(y)
    np.testing.assert_array_equal(filled[1:4], CubicSpline(t[ok], y[ok])(t[1:4]))
    assert mask[1:4].all() and gaps == [(1, 4)]
