"""Force-tube fit (paper Sec. IV-B, "Socket Force Tube"): Bezier bounds of the socket-force
deviation dF = F_s^i - F*_s over the single-support part [tau_lo, tau_hi] of prosthesis stance.

Single support (paper: "We use the x coordinate of the markers on the human foot to
determine whether the human is on single support by the prosthesis or double support, and
remove the double support portion").  Per ps step the human (non-stance) foot is on the
ground at the start (initial double support), lifts off, swings and touches down before the
step ends (final double support).  :func:`single_support_interval` returns the tau of the
first and last frame of the longest swing run, swing meaning: the foot marker's sagittal x
moves forward faster than a threshold (the paper's rule, as in
:func:`characterization.mocap.step_segmentation.single_support`), or its height is above a
threshold, or a contact flag is False.  :func:`tube_interval` aggregates the steps to the
part every step spends in single support: tau_lo = max of the starts, tau_hi = min of the
ends.

The two LPs, per component c in (F_x, F_z, M_y), with s = (tau - tau_lo)/(tau_hi - tau_lo)
and B(s) the Bernstein row of degree m (alpha has m + 1 coefficients):

    upper:  min_alpha  w . alpha   s.t.  B(s_j) alpha >= dF_c,j   for every sample j of every step
    lower:  max_alpha  w . alpha   s.t.  B(s_j) alpha <= dF_c,j

w = :func:`hp_model.bezier.integral_weights` (w . alpha = integral of the curve over s, which
is the paper's integral over tau divided by tau_hi - tau_lo).  Solved with
``scipy.optimize.linprog(method="highs")`` on data scaled by max |dF_c| (tolerances 1e-10 in
those units); afterwards the curve is shifted by the largest remaining solver-tolerance
violation (the Bernstein rows sum to 1, so adding a constant to every coefficient shifts the
curve by that constant), so every sample is inside to rounding.

Certificate (:func:`certify`): every sample inside (relative tolerance 1e-9 of the
component's scale max |dF_c|); tightness, checked literally: moving any one coefficient
inward by delta = 1e-6 x scale (upper down, lower up: the directions that improve the
cost) excludes some sample; and an optimality certificate independent of the solver: non-
negative multipliers on the active samples with sum_j lambda_j B(s_j) = w (KKT, by NNLS).

Credibility (paper's Remark; Campi & Garatti 2008, Calafiore 2010, Garatti & Campi 2022),
all for N steps at confidence 1 - beta:

* a priori, per bound curve (a convex program with d = m + 1 decision variables):
  P{violation probability > eps} <= sum_{i<d} C(N, i) eps^i (1 - eps)^(N - i) = beta, i.e.
  eps = ``scipy.stats.beta.ppf(1 - beta, d, N - d + 1)`` (N = 20, d = 4: 0.344).
* the whole tube (6 curves): a union bound, each curve at beta/6, gives
  sum_c eps_c(beta/6); the 6 LPs taken as one program have d = 6 (m + 1) variables.  Both
  are reported and flagged vacuous when >= 1 (N = 20, m = 3: both are).
* a one-parameter tube (fixed shape, fitted scale, d = 1): eps = 0.139 for N = 20 - valid
  only for a shape chosen without these N steps; reported for comparison.
* a posteriori from the complexity k = number of steps touching the tube (any sample within
  1e-8 x scale of a bound): eps(k) = 1 - t(k), t(k) the unique root in (0, 1) of

      C(N, k) t^(N - k) = (beta / N) sum_{i=k}^{N-1} C(i, k) t^(i - k)         (eps(N) = 1)

  (Garatti & Campi, "Risk and complexity in scenario optimization", Math. Program. 191
  (2022) 243-279, the upper-bound-only form; Campi & Garatti, SYSID 2021 tutorial, eq. 3).
  N = 20, beta = 0.05: eps(0, 1, 2) = 0.197, 0.291, 0.367.  It needs the touching steps to
  be a compression set (refitting with only them gives the same tube): checked and reported.
  Given per curve and for the whole tube (a new step leaving the tube anywhere).
* leave-one-out coverage: the fraction of steps lying entirely inside the tube refitted
  without them (an empirical estimate of the coverage of an (N-1)-step tube).  A step that
  touches no bound cannot leave its own leave-one-out tube (removing an inactive constraint
  keeps the optimum), so only the LPs in which a step is active are refitted.
* every statement assumes independent, identically distributed steps; consecutive steps of
  one person are not independent, so the numbers are optimistic.  Said in the dict.
"""

from __future__ import annotations

import math
import os
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
from scipy.optimize import brentq, linprog, nnls
from scipy.special import gammaln
from scipy.stats import beta as beta_dist

from characterization.gait.bezier_fit import FitError, fit_bezier
from characterization.mocap.limb_angles import runs
from characterization.mocap.step_segmentation import single_support
from hp_model import bezier
from hp_model.atomic_io import atomic_write_bytes
from hp_model.domains import Domain
from hp_model.figures import figure_bytes
from hp_model.force_tube import COMPONENTS, ForceTube

UNITS = ("N", "N", "N m")
SIDES = ("lower", "upper")
REL_TOL = 1e-9  # a sample is inside if it exceeds a bound by at most REL_TOL x scale
REL_DELTA = 1e-6  # the inward move of the tightness check, x scale
REL_ACTIVE = 1e-8  # a sample within REL_ACTIVE x scale of a bound is active ("touches")
LP_TOL = 1e-10  # HiGHS primal/dual feasibility tolerance on the scaled data
DEPENDENCE_NOTE = ("The bounds assume independent, identically distributed steps; "
                   "consecutive steps of one person are not independent, so they are "
                   "optimistic.")

Profile = tuple[np.ndarray, np.ndarray]  # (tau (n,), dF (n, 3))


class TubeFitError(FitError):
    """Profiles that cannot determine or certify a force tube (one-line message)."""


# ---------------------------------------------------------------- single support, nominal

def single_support_interval(tau: np.ndarray, *, foot_x: np.ndarray | None = None,
                            rate: float | None = None, speed_threshold: float = 0.2,
                            foot_height: np.ndarray | None = None,
                            height_threshold: float | None = None,
                            contact: np.ndarray | None = None) -> tuple[float, float]:
    """(tau at lift-off, tau at touch-down) of the human foot in one ps step (module
    docstring).  Give exactly one of: ``foot_x`` (m) with ``rate`` (Hz) - swing where x moves
    forward faster than ``speed_threshold`` (m/s), the paper's rule; ``foot_height`` (m) with
    ``height_threshold`` - swing above it; ``contact`` (True = on the ground)."""
    tau = np.asarray(tau, dtype=float)
    given = [x is not None for x in (foot_x, foot_height, contact)]
    if sum(given) != 1:
        raise TubeFitError("give exactly one of foot_x, foot_height, contact")
    n = tau.size
    if foot_x is not None:
        if rate is None or not rate > 0:
            raise TubeFitError("foot_x needs the frame rate (Hz)")
        if len(foot_x) != n:
            raise TubeFitError(f"foot_x has {len(foot_x)} frames, tau {n}")
        ss = single_support(np.asarray(foot_x, float), rate, 0, n - 1, speed_threshold)
        if ss is None:
            raise TubeFitError("the human foot never moves forward faster than "
                               f"{speed_threshold} m/s: no single support in this step")
        a, b = ss
    else:
        if foot_height is not None:
            if height_threshold is None:
                raise TubeFitError("foot_height needs height_threshold (m)")
            h = np.asarray(foot_height, float)
            swing = np.isfinite(h) & (h > height_threshold)
        else:
            swing = ~np.asarray(contact, bool)
        if swing.size != n:
            raise TubeFitError(f"the foot signal has {swing.size} frames, tau {n}")
        rr = runs(swing)
        if not rr:
            raise TubeFitError("the human foot never leaves the ground: no single support "
                               "in this step")
        a, b = max(rr, key=lambda r: r[1] - r[0])
        b -= 1
    if not (np.isfinite(tau[a]) and np.isfinite(tau[b])) or not tau[b] > tau[a]:
        raise TubeFitError(f"single support frames {a}-{b} do not span an increasing tau")
    return float(tau[a]), float(tau[b])


def tube_interval(intervals: Sequence[tuple[float, float]]) -> tuple[float, float]:
    """[tau_lo, tau_hi] in single support for every step: (max of starts, min of ends)."""
    if not intervals:
        raise TubeFitError("no single-support intervals")
    lo = max(float(a) for a, _ in intervals)
    hi = min(float(b) for _, b in intervals)
    if not hi > lo:
        raise TubeFitError(f"the steps share no single-support part (latest lift-off at tau "
                           f"{lo:.3f}, earliest touch-down at tau {hi:.3f})")
    return lo, hi


def tube_interval_from_steps(steps: Any, domain: str = Domain.PS
                             ) -> tuple[float, float, list[tuple[float, float] | None]]:
    """tau_lo, tau_hi from a :class:`characterization.mocap.steps_artifact.StepsArtifact` (its
    single-support frames, found with the paper's foot-marker rule), and the per-step
    intervals of the ``domain`` steps (None for a step without single support)."""
    per: list[tuple[float, float] | None] = []
    for i in range(steps.n_steps):
        if str(steps.step_domain[i]) != domain:
            continue
        a, b = int(steps.step_ss_start[i]), int(steps.step_ss_end[i])
        if a < 0 or b <= a:
            per.append(None)
            continue
        tau = steps.step_tau(i)
        s0 = int(steps.step_start[i])
        per.append((float(tau[a - s0]), float(tau[b - s0])))
    lo, hi = tube_interval([p for p in per if p is not None])
    return lo, hi, per


def nominal_coefficients(nominal: Any, tau_lo: float, tau_hi: float,
                         degree: int | None = None, n: int = 201) -> np.ndarray:
    """F* over s in [0, 1] (s = (tau - tau_lo)/(tau_hi - tau_lo)) as (3, k+1) Bezier
    coefficients, refitted from a :class:`hp_model.gait_artifact.Gait` (its ``socket_force``
    on the ps phase) or from (3, k+1) coefficients over tau in [0, 1].  ``degree`` defaults to
    the gait's; at that degree the refit is exact (a polynomial restricted to a sub-interval
    is a polynomial of the same degree)."""
    if not (0.0 <= tau_lo < tau_hi <= 1.0):
        raise TubeFitError(f"[tau_lo, tau_hi] = [{tau_lo}, {tau_hi}] is not inside [0, 1]")
    if hasattr(nominal, "socket_force"):
        k0 = nominal.socket_nominal.shape[1] - 1
        force = nominal.socket_force
    else:
        coeffs = np.asarray(nominal, float)
        if coeffs.ndim != 2 or coeffs.shape[0] != 3 or not np.all(np.isfinite(coeffs)):
            raise TubeFitError(f"nominal coefficients must be finite (3, k+1), got "
                               f"{coeffs.shape}")
        k0 = coeffs.shape[1] - 1

        def force(t: np.ndarray) -> np.ndarray:
            return bezier.evaluate(coeffs, t)
    k = k0 if degree is None else int(degree)
    tau = np.linspace(tau_lo, tau_hi, max(n, k + 1))
    fit = fit_bezier((tau - tau_lo) / (tau_hi - tau_lo), force(tau), k)
    return fit.alpha


def deviation_profiles(steps: Sequence[tuple[np.ndarray, np.ndarray]], nominal: np.ndarray,
                       tau_lo: float, tau_hi: float) -> list[Profile]:
    """Per step (tau (n,), F_s (n, 3)) over the whole stance, the samples in [tau_lo, tau_hi]
    (to 1e-9 of its length; tau clipped into it) and their deviation F_s - F*(tau), F* given
    as (3, k+1) coefficients over s."""
    nominal = np.asarray(nominal, float)
    out: list[Profile] = []
    for i, (tau, F) in enumerate(steps):
        tau, F = np.asarray(tau, float).ravel(), np.asarray(F, float)
        if F.shape != (tau.size, 3):
            raise TubeFitError(f"step {i}: F_s has shape {F.shape}, expected ({tau.size}, 3)")
        tol = 1e-9 * (tau_hi - tau_lo)
        keep = (tau >= tau_lo - tol) & (tau <= tau_hi + tol)
        if not keep.any():
            raise TubeFitError(f"step {i}: no sample in [tau_lo, tau_hi] = "
                               f"[{tau_lo:.3f}, {tau_hi:.3f}]")
        t = np.clip(tau[keep], tau_lo, tau_hi)
        s = (t - tau_lo) / (tau_hi - tau_lo)
        out.append((t, F[keep] - bezier.evaluate(nominal, s)))
    return out


def peak_socket_force(steps: Sequence[tuple[np.ndarray, np.ndarray]], tau_lo: float,
                      tau_hi: float) -> list[float]:
    """Per component, the largest |F_s| (N, N, N m) of the steps' (tau, F_s) samples in
    [tau_lo, tau_hi]: the scale the tube's estimation allowance is a fraction of."""
    peak = np.zeros(3)
    for tau, F in steps:
        tau, F = np.asarray(tau, float).ravel(), np.asarray(F, float)
        keep = (tau >= tau_lo) & (tau <= tau_hi)
        if keep.any():
            peak = np.maximum(peak, np.abs(F[keep]).max(axis=0))
    return [float(v) for v in peak]


# ------------------------------------------------------------------------------ the LPs

@dataclass(frozen=True)
class _Data:
    """Pooled samples: s (M,), y (M, 3), step index (M,), basis (M, m+1), scale (3,)."""

    s: np.ndarray
    y: np.ndarray
    step: np.ndarray
    B: np.ndarray
    scale: np.ndarray
    n_steps: int

    @property
    def degree(self) -> int:
        return self.B.shape[1] - 1


def _check_window(profiles: Sequence[Profile], tau_lo: float, tau_hi: float, degree: int
                  ) -> int:
    """The degree as an int, once [tau_lo, tau_hi], the degree and the number of profiles
    can make a bound (else TubeFitError)."""
    if not (math.isfinite(tau_lo) and math.isfinite(tau_hi) and tau_hi > tau_lo):
        raise TubeFitError(f"need finite tau_lo < tau_hi, got [{tau_lo}, {tau_hi}]")
    if isinstance(degree, bool) or int(degree) != degree or not 0 <= degree <= 20:
        raise TubeFitError(f"degree must be an integer in [0, 20], got {degree}")
    degree = int(degree)
    n_steps = len(profiles)
    if n_steps == 0:
        raise TubeFitError("no profiles")
    if n_steps < degree + 1:
        raise TubeFitError(f"{n_steps} profiles cannot support a degree-{degree} bound: need at "
                           f"least degree + 1 = {degree + 1} (scenario theory needs N >= d)")
    return degree


def _checked_profile(i: int, prof: Profile, tau_lo: float, tau_hi: float
                     ) -> tuple[np.ndarray, np.ndarray]:
    """Profile ``i`` as float arrays (tau (n,), dF (n, 3)), refused (TubeFitError) when
    malformed, non-finite or outside [tau_lo, tau_hi]."""
    if len(prof) != 2:
        raise TubeFitError(f"profile {i}: expected (tau, dF)")
    tau, dF = np.asarray(prof[0], float), np.asarray(prof[1], float)
    if tau.ndim != 1 or tau.size == 0:
        raise TubeFitError(f"profile {i}: tau must be a non-empty 1-D array, got shape "
                           f"{tau.shape}")
    if dF.shape != (tau.size, 3):
        raise TubeFitError(f"profile {i}: dF has shape {dF.shape}, expected "
                           f"({tau.size}, 3)")
    if not np.all(np.isfinite(tau)):
        raise TubeFitError(f"profile {i}: non-finite tau ({np.sum(~np.isfinite(tau))} "
                           "samples)")
    bad = ~np.isfinite(dF)
    if bad.any():
        c = COMPONENTS[int(np.flatnonzero(bad.any(axis=0))[0])]
        raise TubeFitError(f"profile {i}: non-finite dF ({int(bad.any(axis=1).sum())} "
                           f"samples, first in {c})")
    tol = 1e-9 * (tau_hi - tau_lo)
    if tau.min() < tau_lo - tol or tau.max() > tau_hi + tol:
        raise TubeFitError(f"profile {i}: tau in [{tau.min():.4f}, {tau.max():.4f}] "
                           f"outside [tau_lo, tau_hi] = [{tau_lo:.4f}, {tau_hi:.4f}]")
    return tau, dF


def _pool(profiles: Sequence[Profile], tau_lo: float, tau_hi: float, degree: int) -> _Data:
    """The profiles' samples pooled over [tau_lo, tau_hi] (s = normalized phase), with the
    degree-``degree`` Bernstein basis at them and each component's scale."""
    degree = _check_window(profiles, tau_lo, tau_hi, degree)
    span = tau_hi - tau_lo
    ss, ys, ks = [], [], []
    for i, prof in enumerate(profiles):
        tau, dF = _checked_profile(i, prof, tau_lo, tau_hi)
        ss.append(np.clip((tau - tau_lo) / span, 0.0, 1.0))
        ys.append(dF)
        ks.append(np.full(tau.size, i))
    s = np.concatenate(ss)
    n_distinct = np.unique(s).size
    if n_distinct < degree + 1:
        raise TubeFitError(f"{n_distinct} distinct sample phases cannot pin a degree-{degree} "
                           f"bound: need at least {degree + 1}")
    y = np.concatenate(ys)
    scale = np.max(np.abs(y), axis=0)
    scale = np.where(scale > 0, scale, 1.0)
    return _Data(s, y, np.concatenate(ks), bezier.basis(degree, s), scale, len(profiles))


def _linprog(B: np.ndarray, y: np.ndarray, sign: float, method: str) -> Any:
    w = bezier.integral_weights(B.shape[1] - 1)
    opts = {"primal_feasibility_tolerance": LP_TOL, "dual_feasibility_tolerance": LP_TOL}
    return linprog(sign * w, A_ub=-sign * B, b_ub=-sign * y, bounds=(None, None),
                   method=method, options=opts)


def _solve(B: np.ndarray, y: np.ndarray, side: str, what: str, method: str = "highs",
           s: np.ndarray | None = None) -> np.ndarray:
    """Coefficients of the upper (min integral, B a >= y) or lower (max integral, B a <= y)
    bound of scaled samples y, shifted so that every sample is inside.

    With the phases ``s``, constraint generation: solve on the extreme sample of each of 64
    phase bins, add the most violated samples, repeat until none is violated; the optimum of
    the reduced LP is then feasible, hence optimal, for the full LP (falls back to the full
    LP if a reduced one is unbounded or does not converge in 20 rounds).  Without ``s``,
    the full LP."""
    m = B.shape[1] - 1
    sign = 1.0 if side == "upper" else -1.0
    a = None
    if s is not None and y.size > 16 * (m + 1):
        key = np.minimum((s * 64).astype(int), 63)
        order = np.lexsort((-sign * y, key))
        first = np.ones(order.size, bool)
        first[1:] = key[order][1:] != key[order][:-1]
        rows = np.zeros(y.size, bool)
        rows[order[first]] = True
        for _ in range(20):
            res = _linprog(B[rows], y[rows], sign, method)
            if res.status != 0:
                break
            viol = sign * (y - B @ res.x)
            bad = viol > LP_TOL
            if not bad.any():
                a = np.asarray(res.x, float)
                break
            worst = np.argsort(-viol)[:max(8, int(bad.sum()) // 4)]
            rows[worst[viol[worst] > LP_TOL]] = True
    if a is None:
        res = _linprog(B, y, sign, method)
        if res.status == 3:
            raise TubeFitError(f"the LP of the {what} is unbounded: the samples do not pin a "
                               f"degree-{m} curve over [tau_lo, tau_hi] (do they cover both "
                               "ends?)")
        if res.status != 0:
            raise TubeFitError(f"the LP of the {what} failed: {res.message}")
        a = np.asarray(res.x, float)
    excess = float(np.max(sign * (y - B @ a)))
    if excess > 0:  # solver tolerance: shift the whole curve out (Bernstein rows sum to 1)
        a = a + sign * excess
    return a


def fit_bound_curve(B: np.ndarray, y: np.ndarray, side: str, s: np.ndarray | None = None,
                    what: str = "bound") -> np.ndarray:
    """One curve of the paper's LPs for any scalar samples: the Bezier coefficients of the
    tightest (least integral) curve with basis rows ``B`` above (``side = "upper"``) or below
    (``"lower"``) every sample ``y`` (scale y to O(1) first: the LP tolerances are absolute);
    ``s``: the samples' phases, for constraint generation.  Raises :class:`TubeFitError`."""
    return _solve(np.asarray(B, float), np.asarray(y, float), side, what, s=s)


def fit_bounds(profiles: Sequence[Profile], tau_lo: float, tau_hi: float, degree: int = 3,
               method: str = "highs", reduce: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """The paper's two LPs for each component: (lower, upper), each (3, degree + 1).
    ``method`` is linprog's; ``reduce=False`` solves the full LPs (no constraint generation)."""
    data = _pool(profiles, tau_lo, tau_hi, degree)
    return _fit(data, np.ones(data.s.size, bool), method, reduce)


def _fit(data: _Data, rows: np.ndarray, method: str = "highs", reduce: bool = True
         ) -> tuple[np.ndarray, np.ndarray]:
    m = data.degree
    out = {side: np.empty((3, m + 1)) for side in SIDES}
    B, s = data.B[rows], (data.s[rows] if reduce else None)
    for c, name in enumerate(COMPONENTS):
        y = data.y[rows, c] / data.scale[c]
        for side in SIDES:
            out[side][c] = _solve(B, y, side, f"{side} bound of {name}", method,
                                  s) * data.scale[c]
    return out["lower"], out["upper"]


# ------------------------------------------------------------------------- certificate

def _slack(data: _Data, coeffs: np.ndarray, c: int, side: str) -> np.ndarray:
    """Distance of every sample inside the bound (negative: outside), in units."""
    curve = data.B @ coeffs
    return curve - data.y[:, c] if side == "upper" else data.y[:, c] - curve


def certify(profiles: Sequence[Profile], lower: np.ndarray, upper: np.ndarray,
            tau_lo: float, tau_hi: float, rel_tol: float = REL_TOL,
            rel_delta: float = REL_DELTA, rel_active: float = REL_ACTIVE) -> dict[str, Any]:
    """Check containment, tightness and optimality of the bounds (module docstring).

    Per component and side: ``max_excess`` (largest amount a sample lies outside, units;
    <= 0 when inside), ``inside``; ``coefficient_tight`` (per coefficient: moving it inward by
    ``rel_delta`` x scale excludes a sample beyond ``rel_tol`` x scale), ``inward_margin``
    (per coefficient: the smallest inward move that puts a sample on the bound, units),
    ``tight``; ``n_active`` samples within ``rel_active`` x scale, ``active_steps``;
    ``kkt_residual`` (relative residual of sum lambda_j B(s_j) = w, lambda >= 0, over the
    active samples) and ``optimal`` (<= 1e-6).  Top level: ``inside``, ``tight``,
    ``optimal`` over all six curves."""
    lower, upper = np.asarray(lower, float), np.asarray(upper, float)
    m = lower.shape[1] - 1
    data = _pool(profiles, tau_lo, tau_hi, m)
    w = bezier.integral_weights(m)
    comps: dict[str, Any] = {}
    inside = tight = optimal = True
    for c, name in enumerate(COMPONENTS):
        sc = float(data.scale[c])
        tol, delta = rel_tol * sc, rel_delta * sc
        comps[name] = {"scale": sc}
        for side, coeffs in (("lower", lower[c]), ("upper", upper[c])):
            sign = 1.0 if side == "upper" else -1.0
            slack = _slack(data, coeffs, c, side)
            ok = bool(np.all(slack >= -tol))
            ctight, margin = [], []
            for i in range(m + 1):
                moved = coeffs.copy()
                moved[i] -= sign * delta
                ctight.append(bool(np.min(_slack(data, moved, c, side)) < -tol))
                bi = data.B[:, i]
                pos = bi > 0
                margin.append(float(np.min(np.maximum(slack[pos], 0) / bi[pos]))
                              if pos.any() else math.inf)
            active = slack <= rel_active * sc
            _, res = nnls(data.B[active].T, w) if active.any() else (None, np.inf)
            kkt = float(res / np.linalg.norm(w))
            comps[name][side] = {
                "max_excess": float(-np.min(slack)), "inside": ok,
                "coefficient_tight": ctight, "tight": all(ctight),
                "inward_margin": [x if math.isfinite(x) else None for x in margin],
                "n_active": int(active.sum()),
                "active_steps": sorted({int(k) for k in data.step[active]}),
                "kkt_residual": kkt if math.isfinite(kkt) else None,
                "optimal": bool(kkt <= 1e-6)}
            inside &= ok
            tight &= all(ctight)
            optimal &= kkt <= 1e-6
    return {"inside": bool(inside), "tight": bool(tight), "optimal": bool(optimal),
            "rel_tol": rel_tol, "rel_delta": rel_delta, "rel_active": rel_active,
            "components": comps}


# ------------------------------------------------------------------------- credibility

def scenario_epsilon(d: int, N: int, beta: float = 0.05) -> float:
    """A-priori violation bound of a convex scenario program with d decision variables and N
    samples at confidence 1 - beta: the eps with sum_{i<d} C(N,i) eps^i (1-eps)^(N-i) =
    beta, i.e. the (1 - beta) quantile of Beta(d, N - d + 1); 1 (vacuous) when d > N."""
    if not 0 < beta < 1 or d < 1 or N < 1:
        raise ValueError(f"need 0 < beta < 1, d >= 1, N >= 1 (got {beta}, {d}, {N})")
    if d > N:
        return 1.0
    return float(beta_dist.ppf(1.0 - beta, d, N - d + 1))


def aposteriori_epsilon(k: int, N: int, beta: float = 0.05) -> float:
    """Garatti & Campi (2022) bound from the complexity k: eps(k) = 1 - t, t in (0, 1) the
    root of C(N,k) t^(N-k) = (beta/N) sum_{i=k}^{N-1} C(i,k) t^(i-k); eps(N) = 1.

    Solved in u = ln t for 1 = (beta/N) sum_i C(i,k)/C(N,k) t^(i-N), whose right side falls
    monotonically from +inf (t -> 0) to beta (N-k) / (N (k+1)) < 1 (t = 1)."""
    if not 0 < beta < 1 or not 0 <= k <= N or N < 1:
        raise ValueError(f"need 0 < beta < 1, 0 <= k <= N (got {beta}, {k}, {N})")
    if k == N:
        return 1.0
    i = np.arange(k, N)
    lc = (gammaln(i + 1) - gammaln(k + 1) - gammaln(i - k + 1)) - (
        gammaln(N + 1) - gammaln(k + 1) - gammaln(N - k + 1))
    base = math.log(beta / N)

    def g(u: float) -> float:
        z = lc + (i - N) * u
        zmax = float(np.max(z))
        return base + zmax + math.log(float(np.sum(np.exp(z - zmax))))

    lo = -1.0
    while g(lo) <= 0:
        lo *= 2
    u = brentq(g, lo, 0.0, xtol=1e-14, rtol=1e-14)
    return float(-math.expm1(u))


def _touching(data: _Data, lower: np.ndarray, upper: np.ndarray, rel_active: float
              ) -> dict[tuple[int, str], np.ndarray]:
    """Per (component, side): boolean (N,) of the steps with a sample on that bound."""
    out = {}
    for c in range(3):
        for side, coeffs in (("lower", lower[c]), ("upper", upper[c])):
            active = _slack(data, coeffs, c, side) <= rel_active * data.scale[c]
            out[(c, side)] = np.bincount(data.step[active], minlength=data.n_steps) > 0
    return out


def _inside_rows(data: _Data, rows: np.ndarray, coeffs: np.ndarray, c: int, side: str,
                 rel_tol: float) -> bool:
    B = data.B[rows]
    y = data.y[rows, c]
    slack = B @ coeffs - y if side == "upper" else y - B @ coeffs
    return bool(np.all(slack >= -rel_tol * data.scale[c]))


def _leave_one_out(data: _Data, lower: np.ndarray, upper: np.ndarray,
                  touching: Mapping[tuple[int, str], np.ndarray],
                  rel_tol: float = REL_TOL) -> np.ndarray:
    """(N,) bool: step i lies entirely inside the tube refitted without step i.  Only the
    LPs in which step i is active are refitted (module docstring)."""
    inside = np.ones(data.n_steps, bool)
    for i in range(data.n_steps):
        rows_i = data.step == i
        for (c, side), touch in touching.items():
            if not touch[i] or not inside[i]:
                continue
            y = data.y[~rows_i, c] / data.scale[c]
            coeffs = _solve(data.B[~rows_i], y, side, f"{side} bound of {COMPONENTS[c]} "
                            f"without step {i}", s=data.s[~rows_i]) * data.scale[c]
            inside[i] = _inside_rows(data, rows_i, coeffs, c, side, rel_tol)
    return inside


def _credibility(data: _Data, lower: np.ndarray, upper: np.ndarray, beta: float = 0.05,
                rel_tol: float = REL_TOL, rel_active: float = REL_ACTIVE) -> dict[str, Any]:
    """The credibility numbers of a fitted tube as plain data (module docstring)."""
    N, m = data.n_steps, data.degree
    d = m + 1
    eps_curve = scenario_epsilon(d, N, beta)
    n_curves = 2 * len(COMPONENTS)
    union_bonf = n_curves * scenario_epsilon(d, N, beta / n_curves)
    d_joint = n_curves * d
    eps_joint = scenario_epsilon(d_joint, N, beta)
    touching = _touching(data, lower, upper, rel_active)
    any_touch = np.any(np.array(list(touching.values())), axis=0)
    k = int(any_touch.sum())
    # compression check: the tube refitted from the touching steps only
    lo_c, hi_c = _fit(data, any_touch[data.step])
    ref = np.maximum(data.scale, 1e-12)[:, None]
    comp_err = float(max(np.max(np.abs(lo_c - lower) / ref), np.max(np.abs(hi_c - upper) / ref)))
    per_curve = {}
    for (c, side), touch in touching.items():
        kc = int(touch.sum())
        per_curve[f"{COMPONENTS[c]}.{side}"] = {
            "k": kc, "steps": np.flatnonzero(touch).tolist(),
            "epsilon_aposteriori": aposteriori_epsilon(kc, N, beta)}
    loo = _leave_one_out(data, lower, upper, touching, rel_tol)
    eps_union = min(1.0, union_bonf)
    return {
        "N": N, "degree": m, "beta": beta, "confidence": 1.0 - beta,
        "a_priori": {
            "d": d, "epsilon_per_curve": eps_curve,
            "statement": (f"each of the {n_curves} bound curves (d = {d}) is exceeded by a "
                          f"new step with probability <= {eps_curve:.3f}, at confidence "
                          f"{1 - beta:.0%}"),
            "union": {
                "curves": n_curves, "epsilon_bonferroni": eps_union,
                "epsilon_bonferroni_raw": union_bonf, "d_joint": d_joint,
                "epsilon_joint": eps_joint,
                "vacuous": bool(union_bonf >= 1.0 and eps_joint >= 1.0),
                "statement": (
                    f"whole tube ({n_curves} curves): union bound sum_c eps_c(beta/"
                    f"{n_curves}) = {union_bonf:.3f}, one program with d = {d_joint}: "
                    f"eps = {eps_joint:.3f}"
                    + (" - vacuous (>= 1): N steps cannot certify the whole tube a priori"
                       if union_bonf >= 1.0 and eps_joint >= 1.0 else "")),
            },
            "fixed_shape_scale_epsilon": scenario_epsilon(1, N, beta),
            "fixed_shape_note": ("a one-parameter tube (fixed shape, fitted scale, d = 1) "
                                 "would give this; valid only for a shape chosen without "
                                 "these steps"),
        },
        "a_posteriori": {
            "formula": ("eps(k) = 1 - t, C(N,k) t^(N-k) = (beta/N) sum_{i=k}^{N-1} C(i,k) "
                        "t^(i-k) (Garatti & Campi 2022)"),
            "touch_rel_tol": rel_active,
            "k_tube": k, "touching_steps": np.flatnonzero(any_touch).tolist(),
            "epsilon_tube": aposteriori_epsilon(k, N, beta),
            "compression_max_rel_error": comp_err,
            "compression_verified": bool(comp_err <= 1e-6),
            "per_curve": per_curve,
        },
        "leave_one_out": {
            "coverage": float(loo.mean()), "inside": int(loo.sum()),
            "outside_steps": np.flatnonzero(~loo).tolist()},
        "independence_note": DEPENDENCE_NOTE,
    }


def credibility(profiles: Sequence[Profile], lower: np.ndarray, upper: np.ndarray,
                tau_lo: float, tau_hi: float, beta: float = 0.05) -> dict[str, Any]:
    """The credibility dict (as stored by :func:`fit_tube`) of given bounds (3, m+1) fitted
    to ``profiles``."""
    lower, upper = np.asarray(lower, float), np.asarray(upper, float)
    return _credibility(_pool(profiles, tau_lo, tau_hi, lower.shape[1] - 1), lower, upper,
                        beta)


# ------------------------------------------------------------------------------ the fit

def fit_tube(profiles: Sequence[Profile], nominal_coeffs: np.ndarray, tau_lo: float,
             tau_hi: float, degree: int = 3, gait_hash: str = "",
             source: Mapping[str, Any] | None = None, beta: float = 0.05) -> ForceTube:
    """Fit, certify and assess the force tube of N deviation profiles (module docstring);
    the tube carries no allowance (:func:`with_allowance` widens it).
    ``profiles``: N pairs (tau (n_i,), dF (n_i, 3)) inside [tau_lo, tau_hi];
    ``nominal_coeffs``: F* as (3, k+1) Bezier coefficients over s (:func:`nominal_coefficients`).
    Raises :class:`TubeFitError` on bad input, or when a sample is outside or a bound has no
    optimality certificate (the literal tightness check is recorded in
    ``credibility["certificate"]``: an optimal bound is tight in exact arithmetic, a failure
    there only means an active sample with a tiny Bernstein weight)."""
    t0 = time.perf_counter()
    nominal = np.asarray(nominal_coeffs, float)
    if nominal.ndim != 2 or nominal.shape[0] != 3 or nominal.shape[1] < 1:
        raise TubeFitError(f"nominal coefficients must have shape (3, k+1), got "
                           f"{nominal.shape}")
    if not np.all(np.isfinite(nominal)):
        raise TubeFitError("nominal coefficients: non-finite values")
    if not 0 < beta < 1:
        raise TubeFitError(f"beta must be in (0, 1), got {beta}")
    data = _pool(profiles, tau_lo, tau_hi, degree)
    lower, upper = _fit(data, np.ones(data.s.size, bool))
    t_lp = time.perf_counter() - t0
    cert = certify(profiles, lower, upper, tau_lo, tau_hi)
    if not cert["inside"]:
        raise TubeFitError("certificate failed: a sample lies outside the fitted tube")
    if not cert["optimal"]:
        bad = [f"{n}.{s}" for n, v in cert["components"].items() for s in SIDES
               if not v[s]["optimal"]]
        raise TubeFitError(f"certificate failed: no optimality certificate for {', '.join(bad)}")
    cred = _credibility(data, lower, upper, beta)
    cred["certificate"] = {
        "inside": cert["inside"], "tight": cert["tight"], "optimal": cert["optimal"],
        "max_rel_excess": max(cert["components"][n][s]["max_excess"]
                              / cert["components"][n]["scale"]
                              for n in COMPONENTS for s in SIDES),
        "n_active": {f"{n}.{s}": cert["components"][n][s]["n_active"]
                     for n in COMPONENTS for s in SIDES},
        "not_tight": [f"{n}.{s}[{i}]" for n in COMPONENTS for s in SIDES
                      for i, ok in enumerate(cert["components"][n][s]["coefficient_tight"])
                      if not ok]}
    gaps = np.diff(np.concatenate([[0.0], np.unique(data.s), [1.0]]))
    src = dict(source or {})
    src.update({"method": "scipy.optimize.linprog(highs)", "n_samples": int(data.s.size),
                "largest_phase_gap": float(gaps.max()),
                "fit_seconds": time.perf_counter() - t0, "lp_seconds": t_lp})
    return ForceTube(gait_hash=gait_hash, tau_lo=float(tau_lo), tau_hi=float(tau_hi),
                     nominal=nominal, lower=lower, upper=upper, n_steps=data.n_steps,
                     credibility=cred, source=src)


def with_allowance(tube: ForceTube, allowance: Sequence[float] | np.ndarray) -> ForceTube:
    """``tube`` widened by ``allowance`` (3,) >= 0 (N, N, N m) for the estimation error of
    its profiles (:class:`hp_model.force_tube.ForceTube`); the certificate and the
    credibility stay those of the certified bounds (widening only adds margin)."""
    allow = np.asarray(allowance, float).reshape(-1)
    if allow.shape != (3,) or not np.all(np.isfinite(allow)) or np.any(allow < 0):
        raise TubeFitError(f"allowance must be 3 finite values >= 0, got {allow}")
    return replace(tube, allowance=allow)


# ---------------------------------------------------------------------- figure, report

def tube_figure_bytes(tube: ForceTube, profiles: Sequence[Profile], fmt: str = "png"
                      ) -> bytes:
    """The paper's Fig. 5: dF of every step (thin) and the tube bounds (thick green), one
    panel per component, against tau."""
    import matplotlib

    matplotlib.use("Agg")
    from matplotlib.figure import Figure

    fig = Figure(figsize=(6.5, 7.5))
    fig.subplots_adjust(left=0.13, right=0.97, top=0.94, bottom=0.07, hspace=0.12)
    axes = fig.subplots(3, 1, sharex=True)
    tau = np.linspace(tube.tau_lo, tube.tau_hi, 301)
    lo, hi = tube.delta_bounds(tau, widened=False)
    wlo, whi = tube.delta_bounds(tau)
    colors = [matplotlib.colormaps["tab20"](i % 20) for i in range(len(profiles))]
    labels = (r"$\Delta F_{s,x}$ [N]", r"$\Delta F_{s,z}$ [N]", r"$\Delta M_{s,y}$ [N m]")
    for c, ax in enumerate(axes):
        for (t, dF), col in zip(profiles, colors, strict=True):
            ax.plot(t, np.asarray(dF)[:, c], lw=0.8, color=col)
        ax.plot(tau, lo[:, c], lw=2.5, color="tab:green")
        ax.plot(tau, hi[:, c], lw=2.5, color="tab:green", label="force tube (certified)")
        if tube.allowance[c] > 0:
            ax.plot(tau, wlo[:, c], lw=1.2, ls="--", color="tab:green")
            ax.plot(tau, whi[:, c], lw=1.2, ls="--", color="tab:green",
                    label="+ estimation allowance")
        ax.set_ylabel(labels[c])
        ax.grid(alpha=0.3)
    axes[0].legend(loc="best", fontsize=8)
    axes[-1].set_xlabel(r"$\tau$")
    axes[-1].set_xlim(tube.tau_lo, tube.tau_hi)
    fig.suptitle(f"Socket-force deviation from nominal: {len(profiles)} steps, "
                 f"degree-{tube.degree} tube", fontsize=10)
    return figure_bytes(fig, fmt)


def save_tube_figure(path: str | os.PathLike[str], tube: ForceTube,
                     profiles: Sequence[Profile]) -> None:
    """Write :func:`tube_figure_bytes` atomically; the format follows the extension."""
    fmt = os.fspath(path).rsplit(".", 1)[-1].lower()
    if fmt not in ("png", "pdf", "svg"):
        raise ValueError(f"{path}: figure format must be png, pdf or svg")
    atomic_write_bytes(path, tube_figure_bytes(tube, profiles, fmt))


def credibility_markdown(cred: Mapping[str, Any]) -> str:
    """Markdown snippet of the credibility dict (``ForceTube.credibility``)."""
    ap, post, loo = cred["a_priori"], cred["a_posteriori"], cred["leave_one_out"]
    un = ap["union"]
    conf = f"{cred['confidence']:.0%}"
    lines = [
        "### Force-tube credibility", "",
        f"N = {cred['N']} steps, degree-{cred['degree']} Bezier bounds, confidence {conf}.",
        "",
        "| statement | k | epsilon |", "|---|---|---|",
        f"| a priori, per bound curve (d = {ap['d']}) | - | {ap['epsilon_per_curve']:.3f} |",
        f"| a priori, whole tube: union of {un['curves']} curves | - | "
        f"{un['epsilon_bonferroni_raw']:.3f}{' (vacuous)' if un['vacuous'] else ''} |",
        f"| a priori, whole tube as one program (d = {un['d_joint']}) | - | "
        f"{un['epsilon_joint']:.3f} |",
        f"| a priori, fixed shape + fitted scale (d = 1; shape not from these steps) | - | "
        f"{ap['fixed_shape_scale_epsilon']:.3f} |",
        f"| a posteriori, whole tube (steps touching any bound) | {post['k_tube']} | "
        f"{post['epsilon_tube']:.3f} |",
    ]
    for name, v in post["per_curve"].items():
        lines.append(f"| a posteriori, {name} | {v['k']} | {v['epsilon_aposteriori']:.3f} |")
    lines += [
        "", f"epsilon bounds the probability that a new step leaves the bound (tube); "
        f"a posteriori: {post['formula']}; compression (refit from the touching steps gives "
        f"the same tube) {'verified' if post['compression_verified'] else 'NOT verified'}.",
        "", f"Leave-one-out coverage: {loo['coverage']:.2f} ({loo['inside']} of {cred['N']} "
        f"steps inside the tube refitted without them"
        + (f"; outside: {loo['outside_steps']}" if loo["outside_steps"] else "") + ").",
        "", f"Note: {cred['independence_note']}", ""]
    return "\n".join(lines)
