"""Socket-force playback and the force tube on the multi-contact graph (a gait from
``gait fit --domains multicontact``; the paper's graph: :mod:`characterization.tube.playback`).

The paper's playback, on the person's graph: each recorded flat prosthesis single support
(``ps``: the human foot off the ground, the prosthesis foot flat, from the human foot's
lift-off to the prosthesis heel off) is fitted with that domain's virtual constraints
(:mod:`hp_model.contact_outputs`) and played back on the full model tracking them exactly.

1. **Strides.** The steps file's complete strides, as the gait fit reads them
   (:func:`characterization.gait.multicontact.take_strides`: the feet's contact events, the
   prosthesis heel off from its sole's pitch, each ankle less its foot's flat pitch).
2. **Fit** (as the gait's curves are regressed from the fitted cycle,
   :func:`characterization.gait.contact_gait.contact_gait_of`): the hip's progress p over the
   sole at each frame gives the window's phase bounds (its first and last frame) and each
   frame's tau; the five y2 joints' angles are fitted by Bezier polynomials of tau of the
   gait's degree, the hip's progress rate (finite differences of p) by a parabola
   (:data:`RATE_DEGREE`), least squares; v_hip = (p_max - p_min) / T.  These are the stride's
   parameters theta_i; the fits' RMS residuals are reported.
3. **Simulate** the full model with all six torques from the feedback linearization of
   theta_i (:class:`hp_model.simulator.HybridSimulator`, mode full; the gait's own ``GAINS``)
   from the surface at tau = 0 (the curves' posture and rates, the stance ankle solving the
   phase, the sole flat at x = 0 and at rest) until tau reaches 1.  The touchdown guard is
   disarmed; the friction cone is reported, not enforced (as the paper's playback).
4. **F_s** at every 1 ms period: the socket rows of the constrained solve (the simulator's
   ``lam`` after the sole's three: the model's eq. (Fsocket), as ``socket_<d>``).

The heel-off part of the single support (``ps_toe``, 70-140 ms on the takes in the tests) is
not played back: fitted on its own few frames, its curves did not meet the state the flat
part ended in, and the feedback linearization's answer to the mismatch put 2-3 kN on the
socket for tens of ms; fitted from that state, 8 frames of degree-5 curves bent as wildly.

Tube: its phase is the prosthesis controllers' stance phase (:class:`hp_model.leg_kinematics.
LegKinematics`: the hip's progress over the heel's ground point from the socket pitch, knee
and ankle), 0 at the nominal walk's prosthesis heel strike and 1 at its toe-off.  F* is the
socket force of the gait as the model walks it (its curves tracked by the full feedback
linearization from the fitted cycle's start, :data:`NOMINAL_STEPS` steps, the last complete
prosthesis stance), the force the controllers' models are linearized about; the fitted
cycle's own wrenches zigzag between collocation nodes and midpoints.  dF = F_s - F*; the tube
lives on [tau_lo, tau_hi] = [the latest single-support start, the earliest end] over the
strides, and is fitted, certified and widened as the paper's
(:func:`characterization.tube.fit.fit_tube`), F* stored as a Bezier fit of degree
:data:`NOMINAL_DEGREE` (its RMS residual in ``source``).  Its ``gait_hash`` is the gait file's
(:attr:`characterization.gait.multicontact_artifact.ContactCycle.hash`).  A lab's take holds
1-3 strides: the default degree is the highest the strides support, at most 3 (degree + 1
strides); the credibility says what so few certify.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from scipy.optimize import brentq

from characterization.gait.bezier_fit import fit_bezier
from characterization.gait.contact_gait import DEGREE, GAINS, contact_gait_of, start_state
from characterization.gait.multicontact import GRAPH, TakeStrides, take_strides
from characterization.gait.multicontact_artifact import ContactCycle
from characterization.mocap.steps_artifact import StepsArtifact
from characterization.tube.fit import (
    Profile,
    TubeFitError,
    credibility_markdown,
    deviation_profiles,
    fit_tube,
    peak_socket_force,
    tube_interval,
    with_allowance,
)
from characterization.tube.model_error import markdown as error_markdown
from characterization.tube.playback import write_tube_files
from hp_model import bezier
from hp_model.closed_loop import ClosedLoop
from hp_model.contact_outputs import ContactConstraints, selection
from hp_model.domains import Domain
from hp_model.force_tube import COMPONENTS, ForceTube
from hp_model.human_prosthesis import HumanProsthesisModel
from hp_model.leg_kinematics import LegKinematics
from hp_model.outputs import GaitParams
from hp_model.simulator import HybridSimulator, SimOptions, SimResult

#: the domain played back: the prosthesis's flat single support
DOMAIN = Domain.PS
#: the prosthesis's stance, heel strike to toe-off
STANCE = (Domain.DS_P, Domain.PS, Domain.PS_TOE, Domain.DS_H)
#: the degree of a recorded window's hip rate: a person's hip slows over the flat foot and
#: speeds up again, a parabola.  The rate is the finite differences of the hip's progress,
#: and on the takes in the tests a quintic through them swung the socket's F_x by up to
#: 2.2 kN (0.3 kN with the parabola); on the gait's own walk the parabola leaves 10 % of
#: F_x's peak in RMS (5 % with a quintic, 43 % with a line: tests/test_contact_tube.py)
RATE_DEGREE = 2
#: the playback runs until its tau reaches 1, at most this times the recorded window's
#: duration
TAU_MAX = 2.0
#: the largest tube degree chosen by default
MAX_DEFAULT_DEGREE = 3
#: steps of the nominal walk whose last complete prosthesis stance gives F*
NOMINAL_STEPS = 4
#: the Bezier degree of F* over the tube's interval
NOMINAL_DEGREE = 8
#: periods of the nominal flat single support left out at its start: the foot's landing
#: (on the committed cycle its first two carry the double support's socket force, -330 N of
#: F_x against -160 N a period later; a tube starting before them bent F*'s Bezier fit by up
#: to 13 N over the next 0.01 of phase and 4 N m at its far end)
LANDING_PERIODS = 2
#: a progress callback: (what, done, total)
Progress = Callable[[str, int, int], None]


class ContactPlaybackError(TubeFitError):
    """Steps and a multi-contact gait that cannot be played back (one-line message)."""


@dataclass(frozen=True)
class StancePlayback:
    """One recorded flat prosthesis single support played back (module docstring): the
    stride, its first and last frame in the steps file, its fitted parameters and their RMS
    residuals (the joints' rad, the hip rate's m/s), the simulated log (1 ms): t (s), q and
    qd (n, 12), the torques u (n, 6; the prosthesis's at the motor), the socket force F_s
    (n, 3: N, N, N m) and the stance phase; the periods with the sole outside the friction
    cone (reported, not enforced)."""

    stride: int
    frames: tuple[int, int]
    params: GaitParams
    fit_rms: np.ndarray
    t: np.ndarray
    q: np.ndarray
    qd: np.ndarray
    u: np.ndarray
    socket: np.ndarray
    phase: np.ndarray
    cone_periods: int
    failed: bool = False
    reason: str = ""

    @property
    def profile(self) -> tuple[np.ndarray, np.ndarray]:
        return self.phase, self.socket

    @property
    def interval(self) -> tuple[float, float]:
        """The single support's span in the stance phase."""
        return float(self.phase[0]), float(self.phase[-1])


@dataclass(frozen=True)
class NominalStance:
    """The gait's prosthesis stance as the model walks it: the stance phase's bounds (the
    hip's progress over the heel, m, at the heel strike and the toe-off) and, over its
    single support, the phase (n,) and the socket force F* (n, 3)."""

    progress: tuple[float, float]
    phase: np.ndarray
    socket: np.ndarray


def socket_rows(log: SimResult) -> np.ndarray:
    """(n, 3) the socket force of each period of a log: its domain's ``lam`` after the
    contact rows."""
    out = np.full((len(log.t), 3), np.nan)
    for code in np.unique(log.domain):
        d = Domain.from_code(int(code))
        k = sum(c.size for c in d.contacts)
        rows = log.domain == code
        out[rows] = log.lam[rows, k:k + 3]
    return out


def tube_progress(tube: ForceTube) -> tuple[float, float]:
    """The hip's progress (m) at a multi-contact tube's stance phase 0 and 1 (ValueError if
    the tube is not one)."""
    p = tube.source.get("stance_progress")
    if not (isinstance(p, list | tuple) and len(p) == 2):
        raise ValueError("the tube has no stance_progress: not a multi-contact tube")
    return float(p[0]), float(p[1])


def share_inside(tube: ForceTube, model: HumanProsthesisModel, log: SimResult) -> float | None:
    """The share of a closed-loop log's flat prosthesis single-support periods in the tube's
    phase range whose socket force lies inside the tube (None without such a period)."""
    rows = np.flatnonzero(log.domain == DOMAIN.code)
    if rows.size == 0:
        return None
    phase = stance_phase(LegKinematics.of(model), model, log.q[rows], tube_progress(tube))
    keep = (phase >= tube.tau_lo) & (phase <= tube.tau_hi)
    if not keep.any():
        return None
    F = socket_rows(log)[rows[keep]]
    return float(np.mean(tube.contains(phase[keep], F - tube.nominal_force(phase[keep]))))


def stance_phase(leg: LegKinematics, model: HumanProsthesisModel, q: np.ndarray,
                 progress: tuple[float, float]) -> np.ndarray:
    """(n,) the stance phase of postures q (n, 12): the sensed progress normalised by the
    bounds ``progress`` (m)."""
    return (leg.progress_of(model, q) - progress[0]) / (progress[1] - progress[0])


def nominal_stance(model: HumanProsthesisModel, cl: ClosedLoop,
                   thetas: Mapping[Domain, np.ndarray], gait: ContactCycle,
                   leg: LegKinematics) -> NominalStance:
    """The gait walked by its own curves (mode full) from the fitted cycle's start, and its
    last complete prosthesis stance (module docstring)."""
    sim = HybridSimulator(model, cl, thetas, np.array(GAINS))
    q0, qd0 = start_state(gait.trajectory)
    log = sim.run(q0, qd0, GRAPH.domains[0], steps=NOMINAL_STEPS, duration=3.0 * NOMINAL_STEPS)
    if log.fall is not None:
        raise ContactPlaybackError(f"the gait does not walk on its own curves: "
                                   f"{log.fall.message()}")
    code = np.asarray(log.domain)
    starts = np.flatnonzero((code[1:] == Domain.DS_P.code) & (code[:-1] != Domain.DS_P.code)) + 1
    ends = np.flatnonzero((code[1:] == Domain.PNS.code) & (code[:-1] == Domain.DS_H.code)) + 1
    pairs = [(a, next(b for b in ends if b > a)) for a in starts if (ends > a).any()]
    if not pairs:
        raise ContactPlaybackError("the gait's walk holds no complete prosthesis stance")
    a, b = pairs[-1]
    bounds = (float(leg.progress_of(model, log.q[a])[0]),
              float(leg.progress_of(model, log.q[b - 1])[0]))
    rows = np.arange(a, b)
    single = rows[code[rows] == DOMAIN.code][LANDING_PERIODS:]
    return NominalStance(bounds, stance_phase(leg, model, log.q[single], bounds),
                         socket_rows(log)[single])


def contact_constraints(cl: ClosedLoop, d: Domain) -> ContactConstraints:
    """The closed loop's virtual constraints of ``d`` on the multi-contact graph."""
    vc = cl.vcs[d]
    if not isinstance(vc, ContactConstraints):
        raise ContactPlaybackError(f"the closed loop's {d} runs the paper's outputs, not the "
                                   "multi-contact graph's")
    return vc


def window_params(vc: ContactConstraints, t: np.ndarray, q: np.ndarray
                  ) -> tuple[GaitParams, np.ndarray]:
    """A domain's parameters fitted to a recorded window (module docstring, item 2): t (n,)
    s, q (n, 12); and the fits' RMS residuals (the joints' rad, the hip rate's m/s)."""
    qd = np.gradient(q, t, axis=0)
    p = np.array([float(vc.progress(q[k], qd[k])[0]) for k in range(len(t))])
    step = p[-1] - p[0]
    if not step > 0:
        raise ContactPlaybackError(f"the hip does not move forward over the "
                                   f"{vc.reference_frame} ({p[0]:.3f} -> {p[-1]:.3f} m)")
    tau = (p - p[0]) / step
    joints = fit_bezier(tau, q @ selection(vc.model, vc.domain.y2_coords).T, DEGREE)
    alpha, rms = np.asarray(joints.alpha, float), np.asarray(joints.rms, float)
    if vc.domain.velocity_output:
        rate = fit_bezier(tau, np.gradient(p, t), RATE_DEGREE)
        alpha, rms = np.r_[alpha, same_degree(rate.alpha, DEGREE)], np.r_[rms, rate.rms]
    return GaitParams(alpha, step / float(t[-1] - t[0]), float(p[0]), float(p[-1])), rms


def same_degree(alpha: np.ndarray, degree: int) -> np.ndarray:
    """Bezier coefficients (rows, m+1) of the same curves at ``degree`` >= m (exact: a
    polynomial of degree m is one of every higher degree)."""
    tau = np.linspace(0.0, 1.0, 4 * (degree + 1))
    return np.asarray(fit_bezier(tau, bezier.evaluate(np.asarray(alpha, float), tau),
                                 degree).alpha, float)


def surface_start(model: HumanProsthesisModel, vc: ContactConstraints, params: GaitParams,
                  q_ref: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(q, qd) on the surface of ``params`` at tau = 0 of the flat-foot domain of ``vc``:
    the y2 joints on their curves, the stance ankle where the hip's progress is p_min, the
    rates on the curves' slopes at the hip's rate V(0), the sole flat at x = 0 and at rest;
    the base's starting guess from ``q_ref``."""
    d = vc.domain
    n_y2 = len(d.y2_coords)
    alpha = np.asarray(params.alpha, float)
    y0 = alpha[:n_y2, 0]
    V0 = float(alpha[n_y2, 0])
    step = params.p_max - params.p_min
    slope = bezier.derivative(alpha[:n_y2])[:, 0] * V0 / step  # dy2/dt = B'(0) tau_dot
    S = selection(model, d.y2_coords)
    ankle = model.coord_names.index(d.stance_leg.ankle)

    def placed(a: float, a_dot: float) -> tuple[np.ndarray, np.ndarray]:
        q, qd = np.array(q_ref, float), np.zeros(model.nq)
        q[np.flatnonzero(S.any(axis=0))] = S[:, S.any(axis=0)].T @ y0
        qd[np.flatnonzero(S.any(axis=0))] = S[:, S.any(axis=0)].T @ slope
        q[ankle], qd[ankle] = a, a_dot
        return model.stance_state(q, qd, d)

    def progress(a: float, a_dot: float = 0.0) -> tuple[float, float]:
        p, p_dot = vc.progress(*placed(a, a_dot))
        return float(p), float(p_dot)

    a0 = float(q_ref[ankle])
    try:
        a = brentq(lambda a: progress(a)[0] - params.p_min, a0 - 0.5, a0 + 0.5, xtol=1e-12)
    except ValueError:
        raise ContactPlaybackError("no stance ankle puts the hip at the window's first "
                                   "progress") from None
    r0, r1 = progress(a, 0.0)[1], progress(a, 1.0)[1]
    return placed(a, (V0 - r0) / (r1 - r0))


def play_stride(model: HumanProsthesisModel, cl: ClosedLoop, thetas: Mapping[Domain, np.ndarray],
                time_s: np.ndarray, strides: TakeStrides, k: int, leg: LegKinematics,
                progress: tuple[float, float]) -> StancePlayback:
    """Play back stride ``k``'s flat prosthesis single support (module docstring, items
    2-4)."""
    a, b = strides.single_supports[k]
    if b - a < DEGREE + 1:
        raise ContactPlaybackError(f"stride {k}: its {DOMAIN} holds {b - a + 1} frames, too "
                                   f"few for degree-{DEGREE} curves")
    if not np.all(np.isfinite(strides.q[a:b + 1])):
        raise ContactPlaybackError(f"stride {k}: a coordinate is unknown in its {DOMAIN}")
    vc = contact_constraints(cl, DOMAIN)
    try:
        params, rms = window_params(vc, np.asarray(time_s[a:b + 1], float), strides.q[a:b + 1])
    except ContactPlaybackError as e:
        raise ContactPlaybackError(f"stride {k}: {e}") from None
    opt = SimOptions(guard_tau_min=math.inf, cone_periods=2**62, tau_max=TAU_MAX,
                     late_touchdown=0.0)
    sim = HybridSimulator(model, cl, {**thetas, DOMAIN: params.pack()}, np.array(GAINS), opt)
    q0, qd0 = surface_start(model, vc, params, strides.q[a])
    log, end = run_domain(sim, q0, qd0, DOMAIN, TAU_MAX * float(time_s[b] - time_s[a]))
    socket = socket_rows(log)
    fz, fx = log.lam[:, 1], log.lam[:, 0]
    cone = int(np.sum((fz <= 0) | (np.abs(fx) > opt.mu * fz)))
    failed = end is None or not np.all(np.isfinite(socket)) or len(log.t) < 2
    reason = (log.fall.message() if log.fall is not None else
              f"its phase did not reach 1 within {TAU_MAX:g} times the recorded window's "
              "duration" if end is None else "non-finite socket force")
    return StancePlayback(
        stride=k, frames=(a, b), params=params, fit_rms=rms, t=log.t, q=log.q, qd=log.qd,
        u=log.u, socket=socket, phase=stance_phase(leg, model, log.q, progress), cone_periods=cone,
        failed=failed, reason=reason if failed else "")


def run_domain(sim: HybridSimulator, q0: np.ndarray, qd0: np.ndarray, domain: Domain,
               longest: float) -> tuple[SimResult, tuple[np.ndarray, np.ndarray] | None]:
    """Simulate (mode full) from (q0, qd0) in ``domain`` until it ends (a lift-off into the
    next domain, or its tau reaching 1), a fall, or ``longest`` s; the log of ``domain``'s
    periods and the state where it ended (None: it did not)."""
    run = sim.start(q0, qd0, domain, mode="full")
    periods = math.ceil(longest / sim.opt.dt)
    while True:
        st = run.observe()
        if st.domain != domain or st.tau >= 1.0:
            return run.result(), (st.q.copy(), st.qd.copy())
        if run.apply(None) is not None or run.periods >= periods:
            return run.result(), None
        run.advance()


@dataclass(frozen=True)
class ContactTubeResult:
    """The played-back single supports, the strides left out (index, why), the tube, its
    deviation profiles (in the stance phase), the nominal stance and the wall times (s)."""

    playbacks: list[StancePlayback]
    skipped: list[tuple[int, str]]
    tube: ForceTube
    profiles: list[Profile]
    nominal: NominalStance
    seconds: dict[str, float] = field(default_factory=dict)


def default_degree(n_strides: int) -> int:
    """The tube's degree when none is given: the highest ``n_strides`` support (degree + 1
    strides), at most :data:`MAX_DEFAULT_DEGREE`."""
    return max(0, min(MAX_DEFAULT_DEGREE, n_strides - 1))


def check_person(steps: StepsArtifact, model: HumanProsthesisModel, src: str = "steps") -> None:
    """Refuse steps of another person than the gait's model (the subject ``mocap process``
    stored with them; its name and notes aside): played back on another body, their socket
    force would be another person's."""
    from characterization.mocap.steps_artifact import steps_subject

    found = steps_subject(steps, src)
    if found is None:
        return

    def body(subject: Any) -> dict[str, Any]:
        return subject.model_dump(mode="json", exclude={"name", "notes"})

    if body(found[0]) != body(model.subject):
        raise ContactPlaybackError(
            f"{src}: field 'subject': the steps are of another person ({found[0].name}, "
            f"{found[0].body_mass:g} kg) than the gait's model ({model.subject.name}, "
            f"{model.subject.body_mass:g} kg); fit the gait from these steps")


def play_strides(gait: ContactCycle, steps: StepsArtifact, progress: Progress | None = None,
                 src: str = "steps"
                 ) -> tuple[list[StancePlayback], list[tuple[int, str]], NominalStance]:
    """Every complete stride's single support played back, the strides left out (index,
    why), and the gait's nominal stance."""
    model = gait.model
    names = [str(c) for c in steps.coord_names]
    if names != list(model.coord_names):
        raise ContactPlaybackError(f"{src}: field 'coord_names' {names} are not the model's "
                                   f"coordinates {list(model.coord_names)}")
    check_person(steps, model, src)
    try:
        strides = take_strides(steps, model, src)
    except ValueError as e:
        raise ContactPlaybackError(str(e)) from None
    if not strides.single_supports:
        raise ContactPlaybackError(
            f"{src}: no prosthesis single support (the human foot's lift-off and its next "
            "touchdown with the prosthesis foot on the ground) to play back; the tube needs "
            "at least 2 (4 for a degree-3 tube): record more walkway trials and pool them "
            "with `hpcosim mocap process A B C --out steps.npz`")
    cl = ClosedLoop(model, DEGREE)
    thetas = contact_gait_of(model, gait.trajectory, gait.durations).thetas()
    leg = LegKinematics.of(model)
    nominal = nominal_stance(model, cl, thetas, gait, leg)
    out: list[StancePlayback] = []
    skipped: list[tuple[int, str]] = []
    n = len(strides.single_supports)
    for k in range(n):
        if progress is not None:
            progress(f"playback of stride {k}", k, n)
        try:
            sp = play_stride(model, cl, thetas, np.asarray(steps.time, float), strides, k, leg,
                             nominal.progress)
        except ContactPlaybackError as e:
            skipped.append((k, str(e)))
            continue
        if sp.failed:
            skipped.append((k, f"playback failed: {sp.reason}"))
        else:
            out.append(sp)
    if progress is not None:
        progress("playback done", n, n)
    return out, skipped, nominal


def fit_contact_tube(gait: ContactCycle, steps: StepsArtifact, degree: int | None = None,
                     allowance: float = 0.01, progress: Progress | None = None,
                     src: str = "steps", gait_src: str = "gait") -> ContactTubeResult:
    """Playback of every complete stride's prosthesis single support and the certified tube
    of their socket-force deviations from the gait's (module docstring), widened by
    ``allowance`` of each component's peak |F_s|."""
    t0 = time.perf_counter()
    if not 0.0 <= allowance < 1.0:
        raise ContactPlaybackError(f"--allowance must be a fraction in [0, 1), got "
                                   f"{allowance}")
    if degree is not None and (isinstance(degree, bool) or int(degree) != degree or degree < 0):
        raise ContactPlaybackError(f"--degree must be a non-negative integer, got {degree}")
    out, skipped, nominal = play_strides(gait, steps, progress, src)
    t_play = time.perf_counter() - t0
    deg = default_degree(len(out)) if degree is None else int(degree)
    if len(out) < max(deg + 1, 2):
        why = "; ".join(f"stride {k}: {r}" for k, r in skipped)
        raise ContactPlaybackError(
            f"{src}: {len(out)} played-back single support(s) cannot support a degree-{deg} "
            f"tube: need at least {max(deg + 1, 2)} (record more strides and pool the takes"
            + (f"; {why})" if why else ")"))
    tube, profiles = tube_around(
        nominal, [sp.profile for sp in out], deg, gait.hash, gait_src,
        {"steps": src, "gait": gait_src, "strides": [sp.stride for sp in out],
         "skipped": [[k, why] for k, why in skipped],
         "fit_rms_max": [float(v) for v in np.max([sp.fit_rms for sp in out], axis=0)],
         "cone_periods": [sp.cone_periods for sp in out], "playback_seconds": t_play})
    tau_lo, tau_hi = tube.tau_lo, tube.tau_hi
    peak = peak_socket_force([sp.profile for sp in out], tau_lo, tau_hi)
    tube = with_allowance(tube, allowance * np.asarray(peak, float))
    return ContactTubeResult(out, skipped, tube, profiles, nominal,
                             {"playback": t_play, "total": time.perf_counter() - t0})


def tube_around(nominal: NominalStance, steps: list[tuple[np.ndarray, np.ndarray]],
                degree: int, gait_hash: str, gait_src: str = "gait",
                source: Mapping[str, Any] | None = None) -> tuple[ForceTube, list[Profile]]:
    """The certified tube (no allowance) of single supports ``steps`` ((stance phase (n,),
    F_s (n, 3)) each) around the gait's F* (module docstring), and their deviation
    profiles: on the phases every step covers, within the gait's own flat single support."""
    tau_lo, tau_hi = tube_interval([(float(t[0]), float(t[-1])) for t, _ in steps])
    tau_lo, tau_hi = max(tau_lo, float(nominal.phase[0])), min(tau_hi, float(nominal.phase[-1]))
    inside = (nominal.phase >= tau_lo) & (nominal.phase <= tau_hi)
    if not tau_hi > tau_lo or inside.sum() < NOMINAL_DEGREE + 1:
        raise ContactPlaybackError(
            f"{gait_src}: the gait's single support covers too little of the recorded ones' "
            f"(stance phase [{tau_lo:.3f}, {tau_hi:.3f}])")
    s = (nominal.phase[inside] - tau_lo) / (tau_hi - tau_lo)
    nfit = fit_bezier(s, nominal.socket[inside], NOMINAL_DEGREE)
    profiles = deviation_profiles(steps, nfit.alpha, tau_lo, tau_hi)
    tube = fit_tube(profiles, nfit.alpha, tau_lo, tau_hi, degree=degree, gait_hash=gait_hash,
                    source={**(source or {}), "domain_graph": GRAPH.value,
                            "phase": "the prosthesis controllers' stance phase",
                            "stance_progress": list(nominal.progress),
                            "nominal_fit_rms": [float(v) for v in nfit.rms]})
    return tube, profiles


def gait_nominal(gait: ContactCycle) -> NominalStance:
    """The gait's nominal stance (:func:`nominal_stance`) with its own closed loop and curves."""
    thetas = contact_gait_of(gait.model, gait.trajectory, gait.durations).thetas()
    return nominal_stance(gait.model, ClosedLoop(gait.model, DEGREE), thetas, gait,
                          LegKinematics.of(gait.model))


def report_markdown(res: ContactTubeResult, steps_src: str = "steps",
                    gait_src: str = "gait") -> str:
    """The Markdown report of a multi-contact tube fit: inputs, per-stride playback, the
    tube, its credibility."""
    t = res.tube
    lines = [
        "# Socket-force tube (multi-contact graph)", "",
        f"Steps `{steps_src}`, gait `{gait_src}` (hash `{t.gait_hash}`); "
        f"{len(res.playbacks)} flat prosthesis single supports played back, "
        f"{len(res.skipped)} left out; degree-{t.degree} Bezier bounds over the stance phase "
        f"[{t.tau_lo:.3f}, {t.tau_hi:.3f}] (the prosthesis controllers' phase: 0 at the "
        "heel strike, 1 at the toe-off of the gait as the model walks it).", "",
        f"Time: playback {res.seconds.get('playback', 0):.2f} s, in all "
        f"{res.seconds.get('total', 0):.2f} s.  F* = the socket force of the gait walked by "
        f"its own curves (RMS of its degree-{NOMINAL_DEGREE} fit: "
        + ", ".join(f"{v:.1f}" for v in t.source.get("nominal_fit_rms", []))
        + " N, N, N m).", "",
        "## Playback", "",
        "| single support | frames | joints' fit RMS (deg, max) | hip rate fit RMS (m/s) "
        "| v_hip (m/s) | stance phase | periods outside cone | status |",
        "|---|---|---|---|---|---|---|---|"]
    skipped = dict(res.skipped)
    for sp in res.playbacks:
        lines.append(f"| {sp.stride} | {sp.frames[0]}-{sp.frames[1]} "
                     f"| {np.degrees(sp.fit_rms[:-1].max()):.2f} | {sp.fit_rms[-1]:.3f} "
                     f"| {sp.params.v_hip:.3f} | {sp.interval[0]:.3f} - {sp.interval[1]:.3f} "
                     f"| {sp.cone_periods} | used |")
    for k, why in skipped.items():
        lines.append(f"| {k} | | | | | | | {why} |")
    lo, hi = t.delta_bounds(np.linspace(t.tau_lo, t.tau_hi, 201))
    lines += ["", "## Tube", "",
              "| component | lower min | upper max | mean width | allowance |",
              "|---|---|---|---|---|"]
    for c, (name, unit) in enumerate(zip(COMPONENTS, ("N", "N", "N m"), strict=True)):
        lines.append(f"| {name} ({unit}) | {lo[:, c].min():.1f} | {hi[:, c].max():.1f} "
                     f"| {np.mean(hi[:, c] - lo[:, c]):.1f} | {t.allowance[c]:.1f} |")
    lines += ["", credibility_markdown(t.credibility)]
    if t.model_error is not None:
        lines += ["", error_markdown(t.model_error)]
    elif "model_error" in t.source:
        lines += ["", f"Model error of clfqp's model: {t.source['model_error']}"]
    return "\n".join(lines)


def write_outputs(out: str | Path, res: ContactTubeResult, steps_src: str = "steps",
                  gait_src: str = "gait") -> dict[str, Path]:
    """Write the figure and the report next to the tube, then the tube (all atomically)."""
    return write_tube_files(out, res.tube, res.profiles,
                            report_markdown(res, steps_src, gait_src))
