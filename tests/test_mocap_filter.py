"""The mocap stage's low-pass and gap filling: each finite run filtered on its own (NaN runs
kept), short gaps filled by the spline through the samples around them."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.interpolate import CubicSpline
from scipy.signal import butter, sosfiltfilt

from characterization.mocap.limb_angles import fill_short_gaps, lowpass


def test_lowpass_keeps_nan_runs_and_filters_each_finite_run() -> None:
    t = np.arange(600) / 120.0
    y = np.sin(2 * np.pi * 1.3 * t) + 0.05 * np.random.default_rng(0).normal(size=600)
    y[200:230] = np.nan
    out = lowpass(y, 120.0, 6.0)
    assert np.isnan(out[200:230]).all()
    sos = butter(2, 6.0 / 60.0, output="sos")
    np.testing.assert_array_equal(out[:200], sosfiltfilt(sos, y[:200]))
    np.testing.assert_array_equal(out[230:], sosfiltfilt(sos, y[230:]))


@pytest.mark.parametrize("n_ok", [2, 3, 4, 50])
def test_gap_fill_is_the_spline_through_the_samples(n_ok: int) -> None:
    t = np.arange(n_ok + 3) / 100.0
    y = np.cos(3 * t)
    y[1:4] = np.nan  # one gap of 3 frames with samples on both sides
    filled, mask, gaps = fill_short_gaps(t, y, 5)
    ok = np.isfinite(y)
    np.testing.assert_array_equal(filled[1:4], CubicSpline(t[ok], y[ok])(t[1:4]))
    assert mask[1:4].all() and gaps == [(1, 4)]
