"""Bezier regression recovers known curves from noisy, stacked, non-monotonic samples."""

from __future__ import annotations

import numpy as np
import pytest

from characterization.gait.bezier_fit import FitError, fit_bezier
from hp_model import bezier


def test_recovers_coefficients_from_stacked_noisy_steps(rng):
    alpha = rng.normal(size=(5, 6))
    sigma = 0.002  # rad
    taus, ys = [], []
    for _ in range(20):  # 20 steps, each with its own uneven, jittered phase samples
        t = np.sort(rng.uniform(-0.02, 1.02, size=80))
        taus.append(t)
        ys.append(bezier.evaluate(alpha, t) + rng.normal(scale=sigma, size=(t.size, 5)))
    fit = fit_bezier(np.concatenate(taus), np.vstack(ys), degree=5)
    assert fit.n == 1600
    # coefficient error ~ sigma * sqrt(cond) / sqrt(N): bounded well below 10 sigma
    assert np.abs(fit.alpha - alpha).max() < 10 * sigma
    np.testing.assert_allclose(fit.rms, sigma, rtol=0.1)  # residual = the noise level
    assert np.all(fit.r2 > 0.99)


def test_degree_zero_is_the_mean(rng):
    y = rng.normal(loc=1.1, scale=0.1, size=300)
    fit = fit_bezier(rng.uniform(size=300), y, degree=0)
    assert fit.alpha.shape == (1, 1)
    assert fit.alpha[0, 0] == pytest.approx(y.mean(), rel=1e-12)


def test_nan_samples_are_skipped_and_bad_inputs_refused(rng):
    t = np.linspace(0, 1, 50)
    y = 2 * t
    y[10] = np.nan
    fit = fit_bezier(t, y, degree=1)
    assert fit.n == 49 and fit.alpha[0] == pytest.approx([0.0, 2.0])
    with pytest.raises(FitError, match="cannot fit"):
        fit_bezier(t[:3], y[:3], degree=5)
    with pytest.raises(FitError, match="do not spread"):
        fit_bezier(np.full(40, 0.5), np.ones(40), degree=3)
    with pytest.raises(FitError, match="phase samples but"):
        fit_bezier(t, y[:-1], degree=1)
