"""``gait fit``: steps -> Bezier regression -> PHZD optimization -> verified gait artifact.

Regression (paper Sec. IV-A): per domain, the data's portions of that domain are stacked;
y2 (the 5 joint angles of ``Domain.y2_coords``) is fitted with Bezier curves of the chosen degree
in the portion's tau; y1's desired value, the hip velocity, is the degree-0 fit (the mean)
of the per-frame d/dt delta_p_hip; the phase bounds are the means of the portions' initial
and final delta_p_hip.

The portions (``segments``): ``"touchdown"`` (default) the model's domains found in the
take, touchdown to touchdown (:mod:`characterization.mocap.domain_segmentation`); ``"paper"``
the paper's steps (delta_p_hip(th_pk, th_pa) rising = ps, falling = pns), whose ps step
also holds the start of the model's pns (see that module).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, replace

import numpy as np

from characterization.gait.bezier_fit import BezierFit, FitError, fit_bezier
from characterization.gait.design import build_gait
from characterization.gait.phzd import (
    DataTargets,
    GaitOptimizationError,
    GaitVerificationError,
    PHZDOptions,
    optimize_gait,
)
from characterization.gait.verification import make_simulator, poincare, simulate_gait
from characterization.mocap.domain_segmentation import domain_segments
from characterization.mocap.step_segmentation import StepBounds
from characterization.mocap.steps_artifact import StepsArtifact
from hp_model import bezier
from hp_model.blas_threads import single_threaded_blas
from hp_model.choices import Choice
from hp_model.config import DeviceConfig, SubjectConfig
from hp_model.domains import PAPER_DOMAINS, Domain
from hp_model.gait_artifact import Gait
from hp_model.human_prosthesis import HumanProsthesisModel, build_tree
from hp_model.outputs import HipProgress, phase
from hp_model.tree import PlanarTree


class FitSegments(Choice):
    """The portions of a take regressed per domain (module docstring)."""

    TOUCHDOWN = "touchdown"  # the model's domains, touchdown to touchdown
    PAPER = "paper"  # delta_p_hip rising = ps, falling = pns


def fit_segments(segments: FitSegments | str) -> FitSegments:
    """``segments`` parsed; a :class:`FitError` (one line naming the choices) otherwise."""
    try:
        return FitSegments(segments)
    except ValueError as e:
        raise FitError(str(e)) from None


@dataclass(frozen=True)
class Regression:
    """The data's gait: targets for the optimization and the goodness of fit."""

    targets: DataTargets
    fits: dict[Domain, BezierFit]  # y2 per domain
    hip_velocity_rms: dict[Domain, float]  # m/s, spread of d/dt delta_p_hip about its mean
    n_steps: dict[Domain, int]
    segments: FitSegments = FitSegments.TOUCHDOWN

    def quality(self) -> dict[Domain, dict]:
        return {d: {"rms": self.fits[d].rms, "r2": np.nan_to_num(self.fits[d].r2, nan=1.0),
                    "n": self.fits[d].n, "steps": self.n_steps[d],
                    "hip_velocity_rms": self.hip_velocity_rms[d],
                    "segments": self.segments} for d in PAPER_DOMAINS}


@dataclass(frozen=True)
class DomainRegression:
    """The regression of some steps of one domain: y2's Bezier fit, v_hip (the mean of the
    per-frame d/dt delta_p_hip) and its spread, the means of the steps' phase bounds."""

    fit: BezierFit
    v_hip: float
    v_hip_rms: float
    p_min: float
    p_max: float
    n_steps: int


def _hip_velocity(vfit: BezierFit, domain: Domain, src: str) -> float:
    """The degree-0 fit of d/dt delta_p_hip (m/s); an error if the hip does not progress."""
    v_hip = float(vfit.alpha[0, 0])
    if not v_hip > 0.05:
        raise FitError(f"{src}: mean hip velocity in '{domain}' is {v_hip:.3f} m/s; "
                       "the steps do not progress forward")
    return v_hip


def regress_domain(model: HumanProsthesisModel, steps: StepsArtifact, indices: Sequence[int],
                   domain: Domain, degree: int, src: str = "steps",
                   windows: Mapping[int, tuple[int, int]] | None = None) -> DomainRegression:
    """Bezier regression of the stacked steps ``indices`` (all of ``domain``); one index
    gives the fit of a single step (playback).  ``windows`` optionally restricts step i's
    samples (y2 and the hip velocity) to its frames [a, b] (both included, counted from
    the step's first frame); tau and the phase bounds stay the whole step's."""
    if not len(indices):
        raise FitError(f"{src}: no '{domain}' step (need at least one step of each domain)")
    names = list(steps.coord_names)
    cols = [names.index(c) for c in Domain(domain).y2_coords]
    hip = HipProgress.of(model, domain)
    k, a = (names.index(c) for c in Domain(domain).stance)
    taus, ys, vels = [], [], []
    for i in indices:
        q = steps.step_q(i)
        delta = hip(q[:, k], q[:, a])
        w = slice(None) if windows is None or i not in windows else \
            slice(windows[i][0], windows[i][1] + 1)
        taus.append(steps.step_tau(i)[w])
        ys.append(q[w, cols])
        vels.append((np.gradient(delta) * steps.frame_rate)[w])
    tau, y, vel = np.concatenate(taus), np.concatenate(ys), np.concatenate(vels)
    fit = fit_bezier(tau, y, degree)
    vfit = fit_bezier(tau, vel, 0)
    sel = np.asarray(indices)
    return DomainRegression(fit, _hip_velocity(vfit, domain, src), float(vfit.rms[0]),
                            float(np.mean(steps.step_delta_lower[sel])),
                            float(np.mean(steps.step_delta_upper[sel])), len(sel))


#: per touchdown portion: frames at each end left out of the regression (the mocap low-pass
#: spreads the impact's velocity jump over them), and frames after/before those whose
#: straight line, extrapolated to the touchdown, gives the phase bound (s; see
#: :func:`regress_segments`)
EDGE_TIME = 0.015
BOUND_FIT_TIME = 0.035


def _segment_phase(delta: np.ndarray, rate: float) -> tuple[float, float, slice] | None:
    """Phase bounds (m) of a touchdown portion and the frames to regress: the touchdowns
    fell on average half a frame outside the portion's end frames; delta_p_hip is
    extrapolated there along straight lines through the frames next to the left-out
    edges (the low-pass bends the end frames)."""
    k = int(np.ceil(EDGE_TIME * rate - 1e-9))
    m = max(2, round(BOUND_FIT_TIME * rate))
    n = len(delta)
    if n < 2 * (k + m):
        return None
    i = np.arange(n, dtype=float)
    p_lo = np.polyval(np.polyfit(i[k:k + m], delta[k:k + m], 1), -0.5)
    p_hi = np.polyval(np.polyfit(i[n - k - m:n - k], delta[n - k - m:n - k], 1), n - 0.5)
    if not p_hi > p_lo:
        return None
    return float(p_lo), float(p_hi), slice(k, n - k)


def regress_segments(model: HumanProsthesisModel, steps: StepsArtifact,
                     segments: Sequence[StepBounds], domain: Domain, degree: int,
                     src: str = "steps") -> DomainRegression:
    """Bezier regression of the stacked touchdown portions ``segments`` (all of
    ``domain``) of the take; tau over each from the stance leg's delta_p_hip and the
    phase bounds of :func:`_segment_phase`.  Portions too short for it, or where the hip
    does not progress, are left out."""
    names = list(steps.coord_names)
    cols = [names.index(c) for c in Domain(domain).y2_coords]
    hip = HipProgress.of(model, domain)
    k, a = (names.index(c) for c in Domain(domain).stance)
    taus, ys, vels, lo, hi = [], [], [], [], []
    for s in segments:
        q = steps.q[s.start:s.end + 1]
        delta = hip(q[:, k], q[:, a])
        bounds = _segment_phase(delta, steps.frame_rate)
        if bounds is None:
            continue
        p_lo, p_hi, keep = bounds
        taus.append(phase(delta, p_lo, p_hi)[keep])
        ys.append(q[keep, cols])
        vels.append((np.gradient(delta) * steps.frame_rate)[keep])
        lo.append(p_lo)
        hi.append(p_hi)
    if not taus:
        raise FitError(f"{src}: no usable '{domain}' portion between touchdowns (need at "
                       "least one of each domain)")
    tau, y, vel = np.concatenate(taus), np.concatenate(ys), np.concatenate(vels)
    fit = fit_bezier(tau, y, degree)
    vfit = fit_bezier(tau, vel, 0)
    return DomainRegression(fit, _hip_velocity(vfit, domain, src), float(vfit.rms[0]),
                            float(np.mean(lo)), float(np.mean(hi)), len(taus))


def regress_steps(model: HumanProsthesisModel, steps: StepsArtifact, degree: int,
                  src: str = "steps", segments: FitSegments | str = FitSegments.TOUCHDOWN
                  ) -> Regression:
    """Bezier regression of the stacked portions of each domain (``segments``: module
    docstring)."""
    segments = fit_segments(segments)
    found = domain_segments(steps) if segments == FitSegments.TOUCHDOWN else []
    alpha, v_hip, p_min, p_max, fits, vrms, counts = {}, {}, {}, {}, {}, {}, {}
    for d in PAPER_DOMAINS:
        if segments == FitSegments.TOUCHDOWN:
            r = regress_segments(model, steps, [s for s in found if s.domain == d], d,
                                 degree, src)
        else:
            idx = [i for i in range(steps.n_steps) if steps.step_domain[i] == d]
            r = regress_domain(model, steps, idx, d, degree, src)
        fits[d], alpha[d] = r.fit, r.fit.alpha
        v_hip[d], vrms[d] = r.v_hip, r.v_hip_rms
        p_min[d], p_max[d] = r.p_min, r.p_max
        counts[d] = r.n_steps
    return Regression(DataTargets(alpha, v_hip, p_min, p_max), fits, vrms, counts, segments)


def output_rms(gait: Gait, n: int = 201) -> dict[Domain, np.ndarray]:
    """Per domain, RMS over tau of y_d(alpha*) - (y_d(alpha_mc) + delta), per output (rad)."""
    s = np.linspace(0.0, 1.0, n)
    out = {}
    for d in PAPER_DOMAINS:
        opt = bezier.evaluate(gait.params[d].alpha, s)
        data = bezier.evaluate(gait.data_params[d].alpha, s) + gait.offsets[d]
        out[d] = np.sqrt(np.mean((opt - data) ** 2, axis=0))
    return out


def verify_gait(model: HumanProsthesisModel, gait: Gait, steps: int = 20) -> dict:
    """Closed-loop checks of a gait (see :mod:`characterization.gait.verification`)."""
    sim = make_simulator(model, gait)
    run = simulate_gait(sim, gait, steps)
    result: dict = {"steps_simulated": run.steps, "simulation_failed": run.failed,
                    "failure": run.reason}
    tr = gait.trajectory[Domain.PS]
    ps0 = np.r_[tr["q"][3:, 0], tr["qd"][3:, 0]]
    dev = [float(np.abs(np.r_[q[3:], qd[3:]] - ps0).max())
           for q, qd in run.post_impact_states(Domain.PS)]
    result["max_deviation_from_optimized_start"] = max(dev) if dev else float("nan")
    try:
        p = poincare(sim, gait)
        result.update(poincare_eigenvalues_abs=np.sort(np.abs(p.eigenvalues))[::-1],
                      spectral_radius=p.spectral_radius,
                      fixed_point_residual=p.fixed_point_residual, stable=p.spectral_radius < 1)
    except RuntimeError as e:
        result.update(spectral_radius=float("nan"), stable=False, poincare_error=str(e))
    result["output_rms_deg"] = {d: np.degrees(v) for d, v in output_rms(gait).items()}
    result["steps_required"] = steps
    result["stable_20_steps"] = bool(not run.failed and run.steps >= steps
                                     and result.get("stable", False))
    return result


def walking_failures(verification: Mapping) -> list[str]:
    """The failed closed-loop checks of a verification record (empty: the gait walks)."""
    failed = []
    n = verification.get("steps_required", 20)
    if verification.get("simulation_failed") or verification.get("steps_simulated", 0) < n:
        failed.append(f"fell after {verification.get('steps_simulated', 0)} of {n} steps "
                      f"({verification.get('failure') or 'no reason given'})")
    rho = float(verification.get("spectral_radius", np.nan))
    if not rho < 1.0:
        why = verification.get("poincare_error")
        failed.append(f"return-map spectral radius {rho:.3g} >= 1" if np.isfinite(rho)
                      else f"return map not computed ({why or 'no fixed point'})")
    return failed


#: m: the legs below the knee, the person's (shank + ankle height) and the prosthesis side
#: (iWalk + pylon + shin + foot), differ by more than this: a warning (a prosthetist cuts
#: the pylon to the user's leg; the default device is cut to the example subject's)
LEG_LENGTH_TOLERANCE = 0.02


def _below(tree: PlanarTree, frame: str, knee: str) -> float:
    """Height (m) of the frame ``knee`` above the frame ``frame`` with every coordinate
    zero (the legs straight down)."""
    def depth(name: str) -> float:
        f = tree.frame(name)
        return f.point[1] + sum(b.placement[1] for b in tree.chain(f.body))
    return depth(knee) - depth(frame)


def leg_lengths(model: HumanProsthesisModel) -> tuple[float, float]:
    """(the person's, the prosthesis side's) length from the knee to the sole (m), from the
    model's tree: shank + ankle height; iWalk + pylon + shin + foot."""
    return _below(model.tree, "l_sole", "l_knee"), _below(model.tree, "p_sole", "r_knee")


def pylon_fitted(subject: SubjectConfig, device: DeviceConfig) -> tuple[DeviceConfig, str]:
    """The device with its pylon (``prosthesis.top.length``) cut so that its prosthesis side
    is as long as the person's leg below the knee, and one line saying so; ``device`` itself
    (and "") when they already differ by no more than :data:`LEG_LENGTH_TOLERANCE`.  A leg
    shorter than the device's knee, shin and foot alone is a one-line :class:`FitError`."""
    tree = build_tree(subject, device)
    human, side = _below(tree, "l_sole", "l_knee"), _below(tree, "p_sole", "r_knee")
    if abs(human - side) <= LEG_LENGTH_TOLERANCE:
        return device, ""
    top = device.prosthesis.top
    length = top.length.value + human - side
    if length <= 0.0:
        raise FitError(f"subject '{subject.name}': the leg below the knee ({human:.3f} m) is "
                       f"shorter than the device's prosthesis side without its pylon "
                       f"({side - top.length.value:.3f} m): give a device that fits (--device)")
    cut = top.length.model_copy(update={
        "value": length, "source": f"cut to subject '{subject.name}''s leg below the knee "
        f"({human:.3f} m) by gait fit"})
    fitted = device.model_copy(update={"prosthesis": device.prosthesis.model_copy(
        update={"top": top.model_copy(update={"length": cut})})})
    return fitted, (f"device: the pylon cut to subject '{subject.name}''s leg below the knee "
                    f"({human:.3f} m): prosthesis.top.length = {length:.3f} m (the device "
                    f"file's {top.length.value:.3f} m; --device FILE to give one)")


#: m: a prosthesis foot whose heel and toe ends are this close to the person's is left as it is
FOOT_TOLERANCE = 0.01


def foot_fitted(subject: SubjectConfig, device: DeviceConfig) -> tuple[DeviceConfig, str]:
    """The device with its foot sized to the person's (a prosthetic foot is chosen by the
    sound foot's size): the same heel and toe ends about the ankle (the heel end and, for a
    subject from a take, the metatarsal heads, where the model's rigid foot rolls off), mass
    and inertia kept; and one line saying so; ``device`` itself (and "") when both ends are
    within :data:`FOOT_TOLERANCE`."""
    L, foot = subject.lengths, device.prosthesis.foot
    toe, heel = L.foot - L.heel, L.heel
    if (abs(foot.length.value - foot.heel.value - toe) <= FOOT_TOLERANCE
            and abs(foot.heel.value - heel) <= FOOT_TOLERANCE):
        return device, ""
    src = f"sized to subject '{subject.name}''s foot by gait fit"
    sized = foot.model_copy(update={
        "length": foot.length.model_copy(update={"value": L.foot, "source": src}),
        "heel": foot.heel.model_copy(update={"value": heel, "source": src})})
    fitted = device.model_copy(update={"prosthesis": device.prosthesis.model_copy(
        update={"foot": sized})})
    return fitted, (f"device: the foot sized to subject '{subject.name}''s: "
                    f"prosthesis.foot.length = {L.foot:.3f} m, heel = {heel:.3f} m (the "
                    f"device file's {foot.length.value:.3f} m, {foot.heel.value:.3f} m; "
                    "--device FILE to give one)")


def worn_device(subject: SubjectConfig, device: DeviceConfig) -> tuple[DeviceConfig, list[str]]:
    """The device the person would wear: its pylon cut to their leg (:func:`pylon_fitted`),
    its foot their foot's size (:func:`foot_fitted`); and the lines saying what changed."""
    device, pylon = pylon_fitted(subject, device)
    device, foot = foot_fitted(subject, device)
    return device, [line for line in (pylon, foot) if line]


def check_subject_fits_steps(model: HumanProsthesisModel, steps: StepsArtifact, src: str
                             ) -> list[str]:
    """Before any optimization (the subject itself is checked when read): the steps hold a
    step (else a one-line :class:`FitError`); returns warnings, one line each: the
    person's leg and the device's prosthesis side of different lengths
    (:data:`LEG_LENGTH_TOLERANCE`)."""
    if not steps.n_steps:
        raise FitError(f"{src}: gait fit: the steps file holds no step")
    human, device = leg_lengths(model)
    if abs(human - device) <= LEG_LENGTH_TOLERANCE:
        return []
    top = model.device.prosthesis.top.length.value + human - device  # the pylon that fits
    return [f"subject '{model.subject.name}': the leg below the knee (shank + ankle height, "
            f"{human:.3f} m) and the device's prosthesis side (iWalk + pylon + shin + foot, "
            f"{device:.3f} m) differ by {abs(human - device) * 1000:.0f} mm: a device whose "
            f"pylon is cut to this leg has prosthesis.top.length = {top:.3f} m (--device)"]


#: (m, m/s): the least step and hip velocity of the second solve when the first collapsed a
#: step (on an 80 kg, 1.80 m subject of openOFM's walk the bounded solve converged in 646
#: iterations and walks: return-map spectral radius 0.052)
STEP_FLOOR = (0.05, 0.05)


def fit_gait(model: HumanProsthesisModel, steps: StepsArtifact, opt: PHZDOptions,
             src: str = "steps", verify: bool = True,
             progress: Callable[[str], None] | None = None,
             segments: FitSegments | str = FitSegments.TOUCHDOWN,
             allow_unstable: bool = False) -> Gait:
    """The whole ``gait fit``: regression (of the portions ``segments``, module
    docstring), optimization, verification.  Raises :class:`GaitOptimizationError` (with
    IPOPT's status) when the optimization fails and :class:`GaitVerificationError` when the
    optimized gait does not walk 20 steps with a contracting return map, unless
    ``allow_unstable`` (then the gait's verification says ``walks: false``).  Every linear
    algebra runs single-threaded, so the result does not depend on the thread settings."""
    say = progress or (lambda _m: None)
    with single_threaded_blas():
        say("Bezier regression of the steps")
        reg = regress_steps(model, steps, opt.degree, src, segments)
        say("PHZD optimization (IPOPT)")
        try:
            res = optimize_gait(model, reg.targets, opt)
        except ValueError:  # IPOPT collapsed a step (p_max = p_min): again with a floor
            say("PHZD optimization (IPOPT) again, the step and hip velocity bounded")
            opt = replace(opt, min_step=STEP_FLOOR[0], min_hip_velocity=STEP_FLOOR[1])
            try:
                res = optimize_gait(model, reg.targets, opt)
            except ValueError as e:  # IPOPT ended on parameters that are no gait
                raise GaitOptimizationError(
                    f"{src}: gait fit, PHZD optimization: IPOPT ended on parameters that are "
                    f"no gait ({e}); no gait written") from None
        if not res.success:
            raise GaitOptimizationError(
                f"the gait optimization did not converge: IPOPT status '{res.status}' after "
                f"{res.iterations} iterations ({res.solve_seconds:.1f} s); no gait written")
        gait = build_gait(model, res, reg.targets, opt, reg.quality())
        if not verify:
            return gait
        say("closed-loop verification (20 steps, return map)")
        v = verify_gait(model, gait)
    failed = walking_failures(v)
    v["walks"] = not failed
    if failed and not allow_unstable:
        raise GaitVerificationError(
            f"{src}: the optimized gait does not walk: {'; '.join(failed)} (IPOPT "
            f"'{res.status}', {res.iterations} iterations); no gait written "
            "(--allow-unstable writes it, marked as not walking)")
    return gait.with_verification(v)
