"""The mocap stage's low-pass and gap filling: each finite run filtered on its own (NaN runs
kept), short gaps filled by the spline through the samples around them; and the numpy
copies of scipy's filter, spline and quaternion conversion the pipeline uses instead of
importing scipy."""

from __future__ import annotations

import platform

import numpy as np
import pytest
from scipy import signal
from scipy.interpolate import CubicSpline
from scipy.spatial.transform import Rotation

from characterization.mocap import butterworth
from characterization.mocap.cubic_spline import not_a_knot_spline
from characterization.mocap.limb_angles import fill_short_gaps, lowpass
from characterization.mocap.quaternion import quaternion_matrices


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


# scipy's compiled LAPACK and PPoly evaluation fuse no multiply-add on x86-64 (checked:
# bit for bit); where a compiler may fuse them (aarch64) the values agree to rounding.
EXACT = platform.machine().lower() in ("x86_64", "amd64")


def _assert_same(ours: np.ndarray, ref: np.ndarray, scale: float) -> None:
    if EXACT:
        np.testing.assert_array_equal(ours, ref)
    else:
        np.testing.assert_allclose(ours, ref, rtol=0, atol=1e-12 * scale)


@pytest.mark.parametrize("n", [2, 3, 4, 5, 7, 60, 5142])
@pytest.mark.parametrize("spacing", ["uniform", "irregular"])
def test_spline_is_scipys_cubic_spline(n: int, spacing: str) -> None:
    """cubic_spline.py against scipy.interpolate.CubicSpline (not imported by the pipeline,
    for its import time): the same values at the knots, between them and at both ends, for
    120 Hz frames and for spacings irregular enough that the solve interchanges rows."""
    rng = np.random.default_rng(n)
    for scale in (1e-3, 1.0, 1e3):
        if spacing == "uniform":
            x = 0.37 + np.arange(n) / 120.0
        else:
            x = np.cumsum(rng.uniform(1e-3, 1.0, n) ** 3)
        y = scale * np.cumsum(rng.standard_normal(n))
        xq = np.concatenate([rng.uniform(x[0], x[-1], 200), x])
        _assert_same(not_a_knot_spline(x, y, xq), CubicSpline(x, y)(xq),
                     scale * np.abs(y).max())


def test_spline_solve_interchanges_rows_as_lapack_does() -> None:
    """A spacing whose third interval exceeds the first two together makes dgtsv pivot
    (|d| < |dl| after the not-a-knot row); the branch is exercised and still scipy's."""
    x = np.array([0.0, 0.01, 0.02, 1.0, 1.01, 3.0, 3.001, 3.002])
    y = np.sin(x) + x ** 2
    # second diagonal after the not-a-knot row: dx0 + dx1, below the next sub-diagonal dx2
    assert (x[1] - x[0]) + (x[2] - x[1]) < x[3] - x[2]  # so rows 2 and 3 are interchanged
    xq = np.linspace(x[0], x[-1], 301)
    _assert_same(not_a_knot_spline(x, y, xq), CubicSpline(x, y)(xq), np.abs(y).max())


def test_spline_refuses_what_it_cannot_draw() -> None:
    with pytest.raises(ValueError, match="two or more"):
        not_a_knot_spline(np.array([0.0]), np.array([1.0]), np.array([0.0]))
    with pytest.raises(ValueError, match="non-finite"):
        not_a_knot_spline(np.arange(4.0), np.array([0, np.nan, 1, 2]), np.array([0.5]))
    with pytest.raises(ValueError, match="strictly increasing"):
        not_a_knot_spline(np.array([0, 1, 1, 2.0]), np.arange(4.0), np.array([0.5]))


def test_quaternion_matrices_are_scipys_rotation() -> None:
    """quaternion.py against scipy.spatial.transform.Rotation (not imported by the pipeline,
    for its import time), normalized and not, at several scales."""
    rng = np.random.default_rng(3)
    for scale in (1e-3, 1.0, 0.999999, 1e3):
        q = scale * rng.standard_normal((20_000, 4))
        _assert_same(quaternion_matrices(q), Rotation.from_quat(q).as_matrix(), 1.0)
    with pytest.raises(ValueError, match="norm zero"):
        quaternion_matrices(np.array([[1.0, 0, 0, 0], [0, 0, 0, 0]]))
    with pytest.raises(ValueError, match=r"\(n, 4\)"):
        quaternion_matrices(np.zeros((3, 3)))
