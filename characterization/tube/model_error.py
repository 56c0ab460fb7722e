"""What the nominal-human model does not explain, characterised offline from playback, and
its mid-stance bound (issue 17, "uncertainty that helps").

The interaction-aware controller (``clfqp``) models the human-prosthesis loop with the
human on the gait's nominal outputs at the measured phase (:mod:`hp_model.interaction`):
the prosthesis's output accelerations nu = (dy1 [m/s^2], d2y2 [rad/s^2]) are a(x_p) +
A(x_p) u_p.  Along a played-back step (:mod:`characterization.tube.playback`: the full 12-DOF
model, every joint on the step's own Bezier fit) the true nu follows from the simulated
prosthesis joint accelerations, and the model error is

    d = nu_true - (a(x_p) + A(x_p) u_p)        (``model_error_ps``, one generated call)

with x_p = (th_pk, th_pa, dth_pk, dth_pa) and u_p the prosthesis motor torques of the
playback, at the GAIT's phase tau(x_p) (the controller's).  On a subject whose steps are the
gait itself d is zero to rounding (the nominal human IS the model there); on a recorded one
it is what the person does differently.

The bound: per component, the paper's two LPs (:func:`characterization.tube.fit.
fit_bound_curve`: the tightest Bezier curve of degree n in s = (tau - tau_lo) / (tau_hi -
tau_lo) above / below every sample), over the mid-stance range [tau_lo, tau_hi] and with the
first ``exclude_after_touchdown`` seconds (default 30 ms) after the prosthesis's touchdown
excluded.  The impact transient is left to the CLF relaxation: a box including it is worth
7-14 motor N m and makes the controller fall (issue 17), without it < 0.1 N m at mid-stance.

Credibility, as for the socket-force tube (:func:`characterization.tube.fit.
credibility`): a priori per curve (d = n + 1), a posteriori from the number k of steps
touching a curve (Garatti & Campi 2022), leave-one-out coverage (steps, and the fraction of
held-out samples inside the bound refitted without their step) and the fraction of the fitted
samples inside (1 by construction).  The same independence caveat applies.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from characterization.tube.fit import (
    DEPENDENCE_NOTE,
    TubeFitError,
    aposteriori_epsilon,
    fit_bound_curve,
    scenario_epsilon,
)
from hp_model import bezier
from hp_model.domains import Domain
from hp_model.force_tube import (
    ERROR_COMPONENTS,
    ERROR_KINDS,
    EXCLUDE_AFTER_TOUCHDOWN,
    ModelErrorBound,
)

REL_ACTIVE = 1e-8  # a sample within this x scale of a curve touches it


@dataclass(frozen=True)
class ErrorSamples:
    """The model error of one step: gait phase tau (n,), time since the prosthesis's
    touchdown (n,) [s], d (n, 2) [m/s^2, rad/s^2]."""

    tau: np.ndarray
    since_touchdown: np.ndarray
    d: np.ndarray


def model_error_samples(model: Any, gait: Any, q: np.ndarray, qd: np.ndarray, u: np.ndarray,
                        since_touchdown: np.ndarray, interaction: Any = None
                        ) -> ErrorSamples:
    """d along logged full-model ps states (q, qd (n, 12), all 6 motor/joint torques u
    (n, 6) as the model's input) of one step: the true prosthesis accelerations from the
    constrained dynamics ``dyn_ps``, the model's from the interaction model at x_p."""
    from hp_model.interaction import InteractionModel

    inter = interaction or InteractionModel(model, gait.degree)
    f = inter.numeric()["model_error_ps"]
    dyn = model.numeric()["dyn_ps"]
    k, a = model.roles[Domain.PS].knee, model.roles[Domain.PS].ankle
    theta, gains = gait.theta(Domain.PS), gait.gains_array
    n = len(q)
    tau, d = np.empty(n), np.empty((n, 2))
    for j in range(n):
        qdd = dyn(q[j], qd[j], u[j])[0]
        x_p = np.array((q[j, k], q[j, a], qd[j, k], qd[j, a]))
        out = f(x_p, theta, gains, np.array((qdd[k], qdd[a])), u[j, 4:6])
        d[j] = out[0].ravel()
        tau[j] = float(out[4][0])
    return ErrorSamples(tau, np.asarray(since_touchdown, float).copy(), d)


def playback_error_samples(model: Any, gait: Any, steps: Sequence[Any]) -> list[ErrorSamples]:
    """:func:`model_error_samples` of played-back steps
    (:class:`characterization.tube.playback.StepPlayback`, each in its own phase): the time since
    the touchdown is the step's phase times its nominal duration
    (``GaitParams.nominal_duration``; y1 = 0 keeps tau_dot constant in playback)."""
    from hp_model.interaction import InteractionModel

    inter = InteractionModel(model, gait.degree)
    out = []
    for sp in steps:
        since = np.asarray(sp.tau, float) * sp.params.nominal_duration
        out.append(model_error_samples(model, gait, sp.q, sp.qd, sp.u, since, inter))
    return out


def _select(samples: Sequence[ErrorSamples], tau_lo: float, tau_hi: float, exclude: float
            ) -> list[tuple[np.ndarray, np.ndarray]]:
    out = []
    for e in samples:
        keep = ((e.tau >= tau_lo) & (e.tau <= tau_hi) & (e.since_touchdown >= exclude)
                & np.all(np.isfinite(e.d), axis=1))
        if keep.any():
            out.append((e.tau[keep], e.d[keep]))
    return out


def common_range(samples: Sequence[ErrorSamples], exclude: float,
                 within: tuple[float, float] | None = None) -> tuple[float, float]:
    """The phase range every step covers past the excluded time: (max of the steps' first
    tau, min of their last), intersected with ``within`` (e.g. the tube's single support)."""
    los, his = [], []
    for e in samples:
        keep = e.since_touchdown >= exclude
        if keep.any():
            los.append(float(e.tau[keep].min()))
            his.append(float(e.tau[keep].max()))
    if not los:
        raise TubeFitError(f"no model-error sample later than {exclude * 1e3:.0f} ms after "
                           "touchdown")
    lo, hi = max(los), min(his)
    if within is not None:
        lo, hi = max(lo, within[0]), min(hi, within[1])
    if not hi > lo:
        raise TubeFitError(f"the steps share no phase range for the model-error bound "
                           f"([{lo:.3f}, {hi:.3f}])")
    return lo, hi


def _fit(per_step: Sequence[tuple[np.ndarray, np.ndarray]], tau_lo: float, tau_hi: float,
         degree: int, components: Sequence[str] = ERROR_COMPONENTS
         ) -> tuple[np.ndarray, np.ndarray]:
    """(lower, upper), (2, degree + 1) each: the LP bounds of the pooled samples."""
    s = np.concatenate([(t - tau_lo) / (tau_hi - tau_lo) for t, _ in per_step])
    y = np.concatenate([d for _, d in per_step])
    B = bezier.basis(degree, np.clip(s, 0.0, 1.0))
    lower, upper = np.empty((2, degree + 1)), np.empty((2, degree + 1))
    for c, name in enumerate(components):
        scale = float(np.max(np.abs(y[:, c]))) or 1.0
        for side, out in (("lower", lower), ("upper", upper)):
            out[c] = fit_bound_curve(B, y[:, c] / scale, side, s,
                                     f"{side} bound of the model error {name}") * scale
    return lower, upper


def _inside(tau: np.ndarray, d: np.ndarray, lower: np.ndarray, upper: np.ndarray,
            tau_lo: float, tau_hi: float, tol: np.ndarray) -> np.ndarray:
    s = np.clip((tau - tau_lo) / (tau_hi - tau_lo), 0.0, 1.0)
    lo, hi = bezier.evaluate(lower, s), bezier.evaluate(upper, s)
    return np.all((d >= lo - tol) & (d <= hi + tol), axis=1)


def credibility(per_step: Sequence[tuple[np.ndarray, np.ndarray]], lower: np.ndarray,
                upper: np.ndarray, tau_lo: float, tau_hi: float, beta: float = 0.05,
                components: Sequence[str] = ERROR_COMPONENTS) -> dict[str, Any]:
    """The credibility of a model-error bound fitted to ``per_step`` (module docstring)."""
    N, m = len(per_step), lower.shape[1] - 1
    y = np.concatenate([d for _, d in per_step])
    scale = np.maximum(np.max(np.abs(y), axis=0), 1e-300)
    tol = 1e-9 * scale
    touching = np.zeros(N, bool)
    per_curve: dict[str, Any] = {}
    for c, name in enumerate(components):
        for side, coeffs in (("lower", lower[c]), ("upper", upper[c])):
            touch = np.zeros(N, bool)
            for i, (t, d) in enumerate(per_step):
                curve = bezier.evaluate(coeffs[None, :],
                                        np.clip((t - tau_lo) / (tau_hi - tau_lo), 0, 1))
                slack = (curve[:, 0] - d[:, c]) if side == "upper" else (d[:, c] - curve[:, 0])
                touch[i] = bool(np.any(slack <= REL_ACTIVE * scale[c]))
            touching |= touch
            per_curve[f"{name}.{side}"] = {"k": int(touch.sum()),
                                           "epsilon_aposteriori": aposteriori_epsilon(
                                               int(touch.sum()), N, beta)}
    inside_fit = np.concatenate([_inside(t, d, lower, upper, tau_lo, tau_hi, tol)
                                 for t, d in per_step])
    # leave-one-out: only a step touching a curve can leave its own refitted bound
    loo: dict[str, Any] = {"step_coverage": None, "inside_steps": None,
                           "held_out_sample_coverage": None}
    if len(per_step) >= m + 2:
        loo_steps = np.ones(N, bool)
        held_in, held_n = 0, 0
        for i, (t, d) in enumerate(per_step):
            held_n += t.size
            if not touching[i]:
                held_in += t.size
                continue
            lo_i, hi_i = _fit([p for j, p in enumerate(per_step) if j != i], tau_lo, tau_hi,
                              m, components)
            ok = _inside(t, d, lo_i, hi_i, tau_lo, tau_hi, tol)
            held_in += int(ok.sum())
            loo_steps[i] = bool(ok.all())
        loo = {"step_coverage": float(loo_steps.mean()), "inside_steps": int(loo_steps.sum()),
               "held_out_sample_coverage": held_in / max(1, held_n)}
    k = int(touching.sum())
    return {
        "N": N, "degree": m, "beta": beta, "confidence": 1.0 - beta,
        "a_priori": {"d": m + 1, "epsilon_per_curve": scenario_epsilon(m + 1, N, beta)},
        "a_posteriori": {"k": k, "touching_steps": np.flatnonzero(touching).tolist(),
                         "epsilon": aposteriori_epsilon(k, N, beta), "per_curve": per_curve},
        "samples_inside_fraction": float(inside_fit.mean()),
        "leave_one_out": loo,
        "independence_note": DEPENDENCE_NOTE,
    }


def fit_model_error(samples: Sequence[ErrorSamples], degree: int = 3,
                    exclude_after_touchdown: float = EXCLUDE_AFTER_TOUCHDOWN,
                    within: tuple[float, float] | None = None,
                    source: Mapping[str, Any] | None = None, beta: float = 0.05,
                    components: tuple[str, str] = ERROR_COMPONENTS) -> ModelErrorBound:
    """The mid-stance bound of the model error of N steps (module docstring; ``components``
    a key of :data:`hp_model.force_tube.ERROR_KINDS`, what the samples' d is); raises
    :class:`TubeFitError` (one line) when the samples cannot determine it."""
    if isinstance(degree, bool) or int(degree) != degree or not 0 <= degree <= 20:
        raise TubeFitError(f"model-error degree must be an integer in [0, 20], got {degree}")
    if not (math.isfinite(exclude_after_touchdown) and exclude_after_touchdown >= 0):
        raise TubeFitError("the excluded time after touchdown must be finite and >= 0")
    tau_lo, tau_hi = common_range(samples, exclude_after_touchdown, within)
    per_step = _select(samples, tau_lo, tau_hi, exclude_after_touchdown)
    if len(per_step) < degree + 1:
        raise TubeFitError(f"{len(per_step)} step(s) with model-error samples cannot support "
                           f"a degree-{degree} bound: need at least {degree + 1}")
    lower, upper = _fit(per_step, tau_lo, tau_hi, degree, components)
    cred = credibility(per_step, lower, upper, tau_lo, tau_hi, beta, components)
    y = np.concatenate([d for _, d in per_step])
    src = dict(source or {})
    src.update({"n_samples": int(y.shape[0]), "units": list(ERROR_KINDS[components]),
                "max_abs": [float(v) for v in np.max(np.abs(y), axis=0)],
                "method": "scipy.optimize.linprog(highs), the force tube's LPs"})
    return ModelErrorBound(tau_lo=tau_lo, tau_hi=tau_hi, lower=lower, upper=upper,
                           exclude_after_touchdown=float(exclude_after_touchdown),
                           n_steps=len(per_step), credibility=cred, source=src,
                           components=components)


def margin_torque(bound: ModelErrorBound, tau: float, A: np.ndarray) -> float:
    """The size of the bound at tau in motor N m: the largest |A^-1 delta| over the box's
    corners delta = (+-r_1, +-r_2) about its centre (the torque the half-width is worth)."""
    lo, hi = bound.bounds(float(tau))
    r = 0.5 * np.maximum(hi - lo, 0.0)
    Ainv = np.linalg.inv(np.asarray(A, float))
    return float(max(np.linalg.norm(Ainv @ (r * np.array(sg)))
                     for sg in ((1, 1), (1, -1))))


def markdown(bound: ModelErrorBound) -> str:
    """Report snippet: range, excluded time, bound sizes and credibility."""
    c = bound.credibility
    tau = np.linspace(bound.tau_lo, bound.tau_hi, 201)
    lo, hi = bound.bounds(tau)
    if bound.components == ERROR_COMPONENTS:
        what = (f"d = nu_true - (a + A u_p) over tau in [{bound.tau_lo:.3f}, "
                f"{bound.tau_hi:.3f}] (the gait's phase), the first "
                f"{bound.exclude_after_touchdown * 1e3:.0f} ms after touchdown excluded (left "
                "to the relaxation)")
    else:
        what = (f"d = qdd_true - qdd_ref - g (u - u_ref) (the multi-contact clfqp's model) over "
                f"the stance phase [{bound.tau_lo:.3f}, {bound.tau_hi:.3f}]")
    lines = ["### Model error of the nominal-human model (clfqp's margin)", "",
             f"{what}; {bound.n_steps} steps, degree-{bound.degree} Bezier bounds.", "",
             "| component | lower min | upper max | mean width | unit |", "|---|---|---|---|---|"]
    for k, (name, unit) in enumerate(zip(bound.components, bound.units, strict=True)):
        lines.append(f"| {name} | {lo[:, k].min():.3g} | {hi[:, k].max():.3g} | "
                     f"{np.mean(hi[:, k] - lo[:, k]):.3g} | {unit} |")
    if c:
        loo = c["leave_one_out"]
        loo_text = ("leave-one-out: not enough steps" if loo["step_coverage"] is None else
                    f"leave-one-out: {loo['step_coverage']:.2f} of the steps and "
                    f"{loo['held_out_sample_coverage']:.3f} of the held-out samples inside")
        lines += ["", f"Credibility at {c['confidence']:.0%}: a priori eps per curve "
                  f"{c['a_priori']['epsilon_per_curve']:.3f}; a posteriori k = "
                  f"{c['a_posteriori']['k']}, eps = {c['a_posteriori']['epsilon']:.3f}; "
                  f"{loo_text}; fitted samples inside: {c['samples_inside_fraction']:.3f}.",
                  "", f"Note: {c['independence_note']}"]
    return "\n".join(lines) + "\n"
