"""Bezier regression of stacked steps (paper Sec. IV-A, "Joint Trajectories from Motion
Capture Data").

With the regressor H_ij = B_{j-1}(tau_i), alpha = (H^T H)^-1 H^T y (solved by least squares,
not the normal equations).  tau need not be unique or monotonic: samples of many steps are
stacked.  Degree 0 is the mean (used for the hip velocity y1).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hp_model import bezier


class FitError(ValueError):
    """Data that cannot determine the requested curve."""


@dataclass(frozen=True)
class BezierFit:
    """Coefficients (n_outputs, m+1) and goodness of fit per output.

    rms: root-mean-square residual (units of y); r2: coefficient of determination (1 is a
    perfect fit; NaN for a constant output); n: number of samples.
    """

    alpha: np.ndarray
    rms: np.ndarray
    r2: np.ndarray
    n: int

    @property
    def degree(self) -> int:
        return self.alpha.shape[1] - 1


def fit_bezier(tau: np.ndarray, y: np.ndarray, degree: int) -> BezierFit:
    """Least-squares Bezier fit of samples y (T,) or (T, n_outputs) at phases tau (T,)."""
    tau = np.asarray(tau, dtype=float).ravel()
    y = np.asarray(y, dtype=float)
    y2 = y[:, None] if y.ndim == 1 else y
    if y2.shape[0] != tau.size:
        raise FitError(f"{tau.size} phase samples but {y2.shape[0]} output samples")
    if degree < 0:
        raise FitError("degree must be >= 0")
    ok = np.isfinite(tau) & np.all(np.isfinite(y2), axis=1)
    tau, y2 = tau[ok], y2[ok]
    if tau.size < degree + 1:
        raise FitError(f"{tau.size} finite samples cannot fit a degree-{degree} curve")
    H = bezier.basis(degree, tau)
    if degree > 0 and np.linalg.matrix_rank(H) < degree + 1:
        raise FitError(f"the phase samples do not spread enough to fit degree {degree}")
    coef, *_ = np.linalg.lstsq(H, y2, rcond=None)
    res = y2 - H @ coef
    rms = np.sqrt(np.mean(res**2, axis=0))
    var = np.var(y2, axis=0)
    with np.errstate(invalid="ignore", divide="ignore"):
        r2 = np.where(var > 0, 1.0 - np.mean(res**2, axis=0) / var, np.nan)
    return BezierFit(alpha=coef.T.copy(), rms=rms, r2=r2, n=int(tau.size))
