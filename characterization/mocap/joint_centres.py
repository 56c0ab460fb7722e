"""Joint centres from one marker on each adjacent limb (paper Sec. II, "Locate Joint
Positions"; the 2-D form of SCoRE).

With markers p1(t), p2(t) (sagittal x, z) on the two limbs and the limb pitches th1(t),
th2(t), the joint is p1 + R(th1) L1 = p2 + R(th2) L2 for constant vectors L1, L2 (marker ->
joint, in each limb's frame; ``R(th) = [[cos, sin], [-sin, cos]]``).  L1, L2 minimise

    sum_t || p1(t) + R(th1(t)) L1 - p2(t) - R(th2(t)) L2 ||^2,

a linear least-squares problem in (L1, L2) (4 unknowns, 2 rows per frame).  The joint
position is the mean of the two estimates.

Well-posedness: the normal matrix is T [[I, -M], [-M^T, I]] with M = mean R(th2 - th1),
whose smallest eigenvalue is T (1 - rho), rho = |mean exp(i (th2 - th1))|.  If the joint
barely rotates (circular SD of th2 - th1 below a threshold) L1, L2 are not identifiable: the
fit is still returned (minimum-norm) but flagged ``well_posed = False`` with the reason.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


def rot(th: np.ndarray) -> np.ndarray:
    """R(th) for an array of angles: (n, 2, 2), body (x, z) -> world."""
    c, s = np.cos(th), np.sin(th)
    return np.stack([np.stack([c, s], -1), np.stack([-s, c], -1)], -2)


@dataclass(frozen=True)
class JointCentreFit:
    """Result for one joint.  ``lam1``, ``lam2``: marker -> joint in limb frames (m);
    ``position`` (n, 2) m, NaN where neither estimate exists; ``residual_rms`` (m): RMS of
    the discrepancy between the two estimates over the fitted frames; ``rotation_sd`` (rad):
    circular SD of the relative angle; ``frames``: number of frames used."""

    joint: str
    lam1: np.ndarray
    lam2: np.ndarray
    position: np.ndarray
    residual_rms: float
    rotation_sd: float
    frames: int
    well_posed: bool
    message: str


def fit_joint_centre(joint: str, p1: np.ndarray, th1: np.ndarray, p2: np.ndarray,
                     th2: np.ndarray, min_rotation: float = np.radians(5.0)) -> JointCentreFit:
    """Solve the paper's least-squares problem for one joint (see module docstring).

    p1, p2: (n, 2) marker positions (m), NaN when lost; th1, th2: (n,) limb pitches (rad).
    Frames with any of the four missing are left out of the fit.
    """
    ok = (np.all(np.isfinite(p1), 1) & np.all(np.isfinite(p2), 1) & np.isfinite(th1)
          & np.isfinite(th2))
    n_ok = int(ok.sum())
    if n_ok < 3:
        nan2 = np.full(2, np.nan)
        return JointCentreFit(joint, nan2, nan2, np.full((len(th1), 2), np.nan), np.nan,
                              np.nan, n_ok, False,
                              f"joint '{joint}': only {n_ok} frames with both markers and "
                              "both limb angles")
    R1, R2 = rot(th1[ok]), rot(th2[ok])
    A = np.concatenate([R1, -R2], axis=2).reshape(-1, 4)  # (2m, 4)
    b = (p2[ok] - p1[ok]).reshape(-1)
    sol, *_ = np.linalg.lstsq(A, b, rcond=None)
    lam1, lam2 = sol[:2], sol[2:]
    rho = float(np.abs(np.mean(np.exp(1j * (th2[ok] - th1[ok])))))
    sd = float(np.sqrt(-2.0 * np.log(max(rho, 1e-300))))
    e1 = p1 + np.einsum("nij,j->ni", rot(th1), lam1)
    e2 = p2 + np.einsum("nij,j->ni", rot(th2), lam2)
    disc = (e1 - e2)[ok]
    res = float(np.sqrt(np.mean(np.sum(disc**2, axis=1))))
    both = np.stack([e1, e2])
    cnt = np.isfinite(both).sum(axis=0)
    pos = np.where(cnt > 0, np.nansum(both, axis=0) / np.maximum(cnt, 1), np.nan)
    well = bool(sd >= min_rotation)
    msg = (f"joint '{joint}': fitted on {n_ok} frames, residual {res * 1000:.1f} mm RMS, "
           f"rotation SD {np.degrees(sd):.1f} deg")
    if not well:
        msg = (f"joint '{joint}': ill-posed: the joint rotates only {np.degrees(sd):.1f} deg "
               f"(circular SD) < {np.degrees(min_rotation):.1f} deg, so the marker-to-joint "
               "vectors are not identifiable; positions are a minimum-norm guess")
    pos.setflags(write=False)
    return JointCentreFit(joint, lam1, lam2, pos, res, sd, n_ok, well, msg)
