"""The numpy low-pass, spline and quaternion code of the mocap stage against scipy's.

``characterization.mocap`` avoids importing scipy.signal, scipy.interpolate and
scipy.spatial on the ``hpcosim mocap process`` path (start-up time, benchmarks/); these are
the functions it uses instead, checked here against the scipy calls they replace.  The
recursions are the same arithmetic in a different order, so the tolerances are rounding:
a few ulp of the signal's scale, growing with the filter's time constant (about 1/wn
samples of accumulated rounding at ~1e-16 each).
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.interpolate import CubicSpline
from scipy.signal import butter, sosfiltfilt
from scipy.spatial.transform import Rotation

from characterization.mocap import butterworth
from characterization.mocap.limb_angles import fill_short_gaps, lowpass
from characterization.mocap.sagittal import quaternion_matrix
from characterization.mocap.spline import cubic_spline


@pytest.mark.parametrize("order", [1, 2, 3, 4, 5, 6])
@pytest.mark.parametrize("wn", [0.01, 0.1, 0.25, 0.6, 0.95])
def test_butterworth_is_scipys(order: int, wn: float) -> None:
    ref = butter(order, wn, output="sos")
    sos = butterworth.butter_sos(order, wn)
    # the same sections; scipy orders the real pole of an odd order differently
    assert sos.shape == ref.shape
    np.testing.assert_allclose(np.sort(sos[:, 3:], axis=0), np.sort(ref[:, 3:], axis=0),
                               rtol=0, atol=1e-15)
    np.testing.assert_allclose(np.prod(sos[:, :3].sum(axis=1) / sos[:, 3:].sum(axis=1)), 1.0,
                               rtol=1e-12)  # unit gain at DC (sums cancel for small wn)
    x = np.cumsum(np.random.default_rng(order).normal(size=3000)) + 5.0
    y = butterworth.sosfiltfilt(sos, x)
    scale = np.abs(x).max()
    assert np.abs(y - sosfiltfilt(ref, x)).max() < 50 * np.finfo(float).eps * scale / wn


def test_lowpass_keeps_nan_runs_and_filters_each_finite_run() -> None:
    t = np.arange(600) / 120.0
    y = np.sin(2 * np.pi * 1.3 * t) + 0.05 * np.random.default_rng(0).normal(size=600)
    y[200:230] = np.nan
    out = lowpass(y, 120.0, 6.0)
    assert np.isnan(out[200:230]).all()
    sos = butter(2, 6.0 / 60.0, output="sos")
    np.testing.assert_allclose(out[:200], sosfiltfilt(sos, y[:200]), rtol=0, atol=1e-14)
    np.testing.assert_allclose(out[230:], sosfiltfilt(sos, y[230:]), rtol=0, atol=1e-14)


def test_short_signals_and_bad_cutoffs() -> None:
    sos = butterworth.butter_sos(2, 0.2)
    with pytest.raises(ValueError, match="longer than 9"):
        butterworth.sosfiltfilt(sos, np.ones(9))
    for order, wn in ((0, 0.2), (2, 0.0), (2, 1.0)):
        with pytest.raises(ValueError, match="Butterworth low-pass"):
            butterworth.butter_sos(order, wn)


@pytest.mark.parametrize("n", [4, 5, 9, 400])
def test_cubic_spline_is_scipys(n: int) -> None:
    rng = np.random.default_rng(n)
    x = np.cumsum(rng.uniform(0.5, 1.5, n)) / 120.0
    y = np.sin(7 * x) + 0.01 * rng.normal(size=n)
    xi = np.linspace(x[0] - 0.02, x[-1] + 0.02, 5 * n)  # inside and beyond the knots
    ref = CubicSpline(x, y)(xi)
    assert np.abs(cubic_spline(x, y, xi) - ref).max() < 100 * np.finfo(float).eps


@pytest.mark.parametrize("n_ok", [2, 3, 4, 50])
def test_gap_fill_is_scipys_spline(n_ok: int) -> None:
    t = np.arange(n_ok + 3) / 100.0
    y = np.cos(3 * t)
    y[1:4] = np.nan  # one gap of 3 frames with samples on both sides
    filled, mask, gaps = fill_short_gaps(t, y, 5)
    ok = np.isfinite(y)
    np.testing.assert_allclose(filled[1:4], CubicSpline(t[ok], y[ok])(t[1:4]), rtol=0,
                               atol=1e-14)
    assert mask[1:4].all() and gaps == [(1, 4)]


def test_quaternion_matrix_is_scipys() -> None:
    q = np.random.default_rng(3).normal(size=(500, 4))  # not normalised
    np.testing.assert_allclose(quaternion_matrix(q), Rotation.from_quat(q).as_matrix(),
                               rtol=0, atol=1e-15)
