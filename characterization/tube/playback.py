"""Socket-force estimation by playback, and the force tube (paper Sec. IV-B).

Playback, per prosthesis-stance (``ps``) step i of a steps artifact:

1. The step's joint trajectories are fitted with Bezier curves in the step's own tau, by the
   same regression as the gait's (:func:`characterization.gait.fit.regress_domain` with this
   one step; degree = the gait's): y2 = the 5 joint angles of ``Domain.PS.y2_coords``; v_hip =
   the mean of the per-frame d/dt delta_p_hip over the fitted frames; the phase bounds are
   the step's own delta_p_hip at its first and last frame. These parameters alpha^pb_i are
   the step's gait theta_i. Frames fitted (:func:`fit_window`,
   ``PlaybackOptions.fit_margin``): by default the step's single support (the foot-marker
   rule's frames) widened by 0.1 in tau on each side; ``fit_margin=None`` fits every frame of
   the step (the paper). Measured (README, "Socket-force playback"): the whole-step fit has to
   bend through the double-support frames (for a model-generated subject, frames after the
   human foot's touchdown), which biases the accelerations, hence F_s, over single support
   (M_y by about 10 % of its peak).
2. Start on that step's zero-dynamics surface at the window's first tau (0 for the whole
   step): the nominal posture of theta_i at that tau moving at its nominal rate, placed on
   the stance foot at x = 0 (``zero_dynamics_ps`` of :mod:`hp_model.placement`;
   y1 = y2 = dy2 = 0 exactly).
3. Simulate the full 12-DOF model, all 6 torques from the feedback linearization of the
   step's outputs (:class:`hp_model.simulator.HybridSimulator`, mode "full"), until tau
   reaches the window's end (1 for the whole step): duration ceil(T / dt) dt with T the
   window's share of the step's nominal duration (``GaitParams.nominal_duration``; y1 = 0
   keeps tau_dot constant).  The touchdown
   guard is disarmed by default, so the ps domain covers the window even where the recorded
   human foot is already on the ground (those frames are removed afterwards, as in the
   paper); with ``stop_at_touchdown`` the run also ends at the human foot's touchdown.
   The stance-foot friction-cone check is not a failure here (playback replays data that need
   not respect the model's friction); the frames outside the cone are counted and reported.
   A playback that falls (hip below ``min_hip_height``, phase reversed, non-finite state) is
   skipped and reported.
4. At every logged instant (1 kHz), F_s = ``socket_ps(q, qd, u, lam_foot)``: the paper's eq.
   (Fsocket) with the stance-foot wrench lam_foot (rows 0:3 of the constrained solve) moved
   to the known side.  It equals the socket rows 3:6 of the full KKT solve; the largest
   relative difference is recorded per step (``kkt_residual``; about 1e-13).

Tube: dF_s^i(tau) = F_s^i(tau) - F*(tau) for (F_x, F_z, M_y), F* the gait's nominal socket
force. tau is, by default (``PlaybackOptions.tube_phase = "gait"``), the GAIT's phase of
each sample (its delta_p_hip normalised by the gait's phase bounds p_min*, p_max*): the
phase F* is a function of and the one the controllers compute from the prosthesis's angles.
Each step's own tau (the paper's per-step normalization, ``"step"``) puts a sample of the
same configuration at another phase: a recorded step spans more hip progress than the gait's
ps, and F* is then compared at the wrong place (on the demo subject: a tube ~30 % wider,
centred up to 50 N away from F*). Double support is removed by the paper's foot-marker rule:
the steps artifact's single-support frames (human foot marker x moving forward faster than
the threshold) give each step's [tau_a, tau_b]; the tube lives on [tau_lo, tau_hi] = [max
tau_a, min tau_b] (:func:`characterization.tube.fit.tube_interval`), within [0, 1] in
the gait's phase. Then the LPs, the certificate and the credibility of
:func:`characterization.tube.fit.fit_tube`; the tube records the gait's hash. Steps in
which the foot-marker rule found no single support are skipped.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from characterization.gait.bezier_fit import FitError
from characterization.gait.fit import regress_domain
from characterization.mocap.steps_artifact import StepsArtifact
from characterization.tube.fit import (
    Profile,
    TubeFitError,
    credibility_markdown,
    deviation_profiles,
    fit_tube,
    nominal_coefficients,
    peak_socket_force,
    save_tube_figure,
    tube_interval,
    with_allowance,
)
from characterization.tube.model_error import (
    fit_model_error,
    playback_error_samples,
)
from characterization.tube.model_error import markdown as model_error_markdown
from hp_model.atomic_io import atomic_write_text
from hp_model.closed_loop import ClosedLoop
from hp_model.domains import PAPER_DOMAINS, Domain
from hp_model.force_tube import COMPONENTS, EXCLUDE_AFTER_TOUCHDOWN, ForceTube, TubePhase, save_tube
from hp_model.gait_artifact import Gait
from hp_model.human_prosthesis import HumanProsthesisModel
from hp_model.outputs import GaitParams
from hp_model.simulator import HybridSimulator, SimOptions

DOMAIN = Domain.PS
#: default estimation allowance of the tube, a fraction of each component's peak |F_s|: on
#: the model-generated subject the true profiles leave the bare tube by <= 0.3 % of peak
#: without noise and <= 0.8 % with 0.05 deg of angle noise (README table)
DEFAULT_ALLOWANCE = 0.01
#: a progress callback: (what, done, total)
Progress = Callable[[str, int, int], None]


class PlaybackError(FitError):
    """Steps and gait that cannot be played back (one-line message)."""


@dataclass(frozen=True)
class PlaybackOptions:
    """Integration settings of the playback (SI units)."""

    dt: float = 1e-3  # s, log period (one F_s sample per period)
    substeps: int = 2  # RK4 steps per period
    stop_at_touchdown: bool = False  # also end a step at the human foot's touchdown
    #: frames of each step's Bezier fit and span of its playback: None = the whole step (the
    #: paper); m = the single support found by the foot-marker rule, widened by m in tau
    fit_margin: float | None = 0.1
    min_hip_height: float = 0.55  # m, below it the playback counts as fallen
    mu: float = 0.8  # friction coefficient of the (reported, not enforced) cone check
    #: the phase the tube is a function of: "gait" = the gait's tau of each sample's
    #: configuration (:mod:`hp_model.outputs`), the phase the controllers compute; "step" =
    #: each step's own tau (its own phase bounds, the paper's per-step normalization)
    tube_phase: TubePhase = TubePhase.GAIT

    def __post_init__(self) -> None:
        try:
            object.__setattr__(self, "tube_phase", TubePhase(self.tube_phase))
        except ValueError as e:
            raise PlaybackError(str(e)) from None

    def sim_options(self) -> SimOptions:
        return SimOptions(dt=self.dt, substeps=self.substeps,
                          guard_tau_min=0.6 if self.stop_at_touchdown else math.inf,
                          min_hip_height=self.min_hip_height, tau_max=1.3,
                          late_touchdown=0.0,  # the playback's own bound, in phase
                          cone_periods=2**62, mu=self.mu)


@dataclass(frozen=True)
class TubeOptions:
    """What the fitted tube is: the Bezier degree of its bounds, the confidence parameter
    beta of its credibility, its widening for the playback's estimation error (a fraction
    of each component's peak |F_s| over the played-back window; 0: the paper's bare tube),
    and the model-error bound of ``clfqp`` (:mod:`characterization.tube.model_error`):
    whether to fit it, its degree and the time after each touchdown left out (s)."""

    degree: int = 3
    beta: float = 0.05
    allowance: float = DEFAULT_ALLOWANCE
    model_error: bool = True
    error_degree: int = 3
    exclude_after_touchdown: float = EXCLUDE_AFTER_TOUCHDOWN


def phase_map(step: GaitParams, gait: GaitParams, tau: np.ndarray | float) -> np.ndarray:
    """A step's tau (its own phase bounds) as the phase of ``gait``: the same hip progress
    delta_p_hip, normalised by the gait's bounds (affine)."""
    return gait.phase_of(step.delta_p_at(np.asarray(tau, float)))


@dataclass(frozen=True)
class StepPlayback:
    """One played-back ps step: the fitted parameters and the simulated log, F_s per frame."""

    step: int  # index of the step in the steps artifact
    params: GaitParams  # alpha^pb_i, v_hip, the step's own phase bounds
    fit_rms: np.ndarray  # (5,) rad, RMS residual of the Bezier fit of the step's joints
    t: np.ndarray  # (n,) s
    tau: np.ndarray  # (n,)
    q: np.ndarray  # (n, 12)
    qd: np.ndarray
    u: np.ndarray  # (n, 6)
    lam: np.ndarray  # (n, 6) foot wrench, socket rows of the KKT solve
    socket: np.ndarray  # (n, 3) F_s by eq. (Fsocket)
    single_support: tuple[float, float] | None  # tau at lift-off / touch-down (marker rule)
    kkt_residual: float  # max |F_s - lam[3:6]| / max |lam[3:6]|
    cone_frames: int  # frames with the stance foot pulling or outside the friction cone
    touchdown_tau: float | None  # with stop_at_touchdown, the tau of the touchdown
    failed: bool = False
    reason: str = ""

    @property
    def profile(self) -> tuple[np.ndarray, np.ndarray]:
        return self.tau, self.socket

    def in_phase_of(self, gait: GaitParams) -> StepPlayback:
        """This playback with tau (and its single support) re-expressed in the phase of
        ``gait`` (:func:`phase_map`)."""
        def tau_g(tau):
            return phase_map(self.params, gait, tau)

        ss = None if self.single_support is None else (
            float(tau_g(self.single_support[0])), float(tau_g(self.single_support[1])))
        td = None if self.touchdown_tau is None else float(tau_g(self.touchdown_tau))
        return replace(self, tau=tau_g(self.tau), single_support=ss, touchdown_tau=td)


@dataclass(frozen=True)
class Playback:
    """All played-back steps, the ones skipped (step index, reason) and the wall time."""

    steps: list[StepPlayback]
    skipped: list[tuple[int, str]]
    seconds: float

    @property
    def good(self) -> list[StepPlayback]:
        return [s for s in self.steps if not s.failed and s.single_support is not None]


@dataclass(frozen=True)
class TubeResult:
    """A fitted tube with its inputs.  ``playback`` keeps each step in its own phase (the
    playback's); ``profiles`` and the tube are in ``phase`` (``PlaybackOptions.tube_phase``),
    the gait's when ``gait_ps`` is its ps parameters."""

    tube: ForceTube
    profiles: list[Profile]  # (tau, dF) per step in the tube, inside [tau_lo, tau_hi]
    playback: Playback
    used: list[int]  # step indices in the tube
    seconds: dict[str, float] = field(default_factory=dict)
    phase: TubePhase = TubePhase.STEP
    gait_ps: GaitParams | None = None

    def tube_tau(self, sp: StepPlayback, tau: np.ndarray | float) -> np.ndarray:
        """A phase of step ``sp`` (its own tau) in the tube's phase."""
        if self.phase == TubePhase.GAIT and self.gait_ps is not None:
            return phase_map(sp.params, self.gait_ps, tau)
        return np.asarray(tau, float)


# ---------------------------------------------------------------------------- checks

def ps_steps(steps: StepsArtifact, n_steps: int | None = None, src: str = "steps"
             ) -> list[int]:
    """Indices of the first ``n_steps`` ps steps (all by default)."""
    idx = [i for i in range(steps.n_steps) if str(steps.step_domain[i]) == DOMAIN]
    if not idx:
        raise PlaybackError(f"{src}: no prosthesis-stance (ps) step to play back "
                            f"({steps.n_steps} steps, all pns)")
    if n_steps is not None:
        if n_steps < 1:
            raise PlaybackError(f"--steps must be >= 1, got {n_steps}")
        idx = idx[:n_steps]
    return idx


def check_inputs(model: HumanProsthesisModel, gait: Gait, steps: StepsArtifact,
                 src: str = "steps") -> None:
    """Refuse a gait made for another model and steps processed for another model."""
    gait.check_model(model.parameter_hash())
    names = [str(c) for c in steps.coord_names]
    if names != list(model.coord_names):
        raise PlaybackError(f"{src}: field 'coord_names' {names} are not the model's "
                            f"coordinates {list(model.coord_names)}")
    for r, d in enumerate(PAPER_DOMAINS):
        mine = np.array(model.hip_progress_coefficients(d))
        if not np.allclose(steps.hip_coefficients[r], mine, rtol=1e-9, atol=1e-12):
            raise PlaybackError(
                f"{src}: field 'hip_coefficients': the steps were processed with "
                f"delta_p_hip coefficients {steps.hip_coefficients[r].tolist()} ({d}), the "
                f"model has {mine.tolist()}; process the take for this subject/device")


# ------------------------------------------------------------------------ one step

def fit_window(steps: StepsArtifact, i: int, margin: float | None
               ) -> tuple[float, float, slice]:
    """(tau_start, tau_end, frames) of step i's Bezier fit and playback: the whole step when
    ``margin`` is None (the paper) or the step has no single support, else the foot-marker
    rule's single support widened by ``margin`` (tau) on each side, within [0, 1]."""
    ss = single_support_tau(steps, i)
    if margin is None or ss is None:
        return 0.0, 1.0, slice(None)
    if not margin >= 0:
        raise PlaybackError(f"the fit margin must be >= 0, got {margin}")
    tau = steps.step_tau(i)
    lo, hi = max(0.0, ss[0] - margin), min(1.0, ss[1] + margin)
    rows = np.flatnonzero((tau >= lo) & (tau <= hi))
    return float(tau[rows[0]]), float(tau[rows[-1]]), slice(int(rows[0]), int(rows[-1]) + 1)


def step_params(model: HumanProsthesisModel, steps: StepsArtifact, i: int, degree: int,
                src: str = "steps", margin: float | None = None
                ) -> tuple[GaitParams, np.ndarray]:
    """The step's gait parameters (its own Bezier fit, v_hip, phase bounds) and the fit's
    RMS residual per joint; the fit uses the frames of :func:`fit_window`."""
    w = fit_window(steps, i, margin)[2]
    windows = None if w == slice(None) else {i: (w.start, w.stop - 1)}
    try:
        r = regress_domain(model, steps, [i], DOMAIN, degree, f"{src}: step {i}", windows)
    except FitError as e:
        raise PlaybackError(str(e)) from None
    return GaitParams(r.fit.alpha, r.v_hip, r.p_min, r.p_max), np.asarray(r.fit.rms)


def zero_dynamics_state(closed_loop: ClosedLoop, params: GaitParams, tau: float = 0.0
                        ) -> tuple[np.ndarray, np.ndarray]:
    """(q, qd) on the zero-dynamics surface of ``params`` at phase ``tau`` with
    d/dt delta_p_hip = v_hip: y1 = y2 = dy2 = 0, stance foot flat at x = 0 and at rest
    (``zero_dynamics_ps`` of :mod:`hp_model.placement`)."""
    return closed_loop.zero_dynamics_state(DOMAIN, tau, params.pack())


def socket_forces(model: HumanProsthesisModel, q: np.ndarray, qd: np.ndarray, u: np.ndarray,
                  lam_foot: np.ndarray, domain: str = DOMAIN) -> np.ndarray:
    """F_s (n, 3) by the paper's eq. (Fsocket), ``socket_<domain>`` compiled, per frame."""
    f = model.numeric()[f"socket_{domain}"]
    out = np.empty((len(q), 3))
    for j in range(len(q)):
        out[j] = f(q[j], qd[j], u[j], lam_foot[j])[0]
    return out


def single_support_tau(steps: StepsArtifact, i: int) -> tuple[float, float] | None:
    """The step's single-support interval in its tau (the artifact's frames, found with the
    paper's foot-marker rule), None when the rule found none."""
    a, b = int(steps.step_ss_start[i]), int(steps.step_ss_end[i])
    if a < 0 or b <= a:
        return None
    tau = steps.step_tau(i)
    s0 = int(steps.step_start[i])
    ta, tb = float(tau[a - s0]), float(tau[b - s0])
    return (ta, tb) if tb > ta else None


def play_step(model: HumanProsthesisModel, closed_loop: ClosedLoop, gait: Gait,
              steps: StepsArtifact, i: int, options: PlaybackOptions | None = None,
              src: str = "steps") -> StepPlayback:
    """Play back ps step ``i`` (module docstring, items 1-4)."""
    opt = options or PlaybackOptions()
    if str(steps.step_domain[i]) != DOMAIN:
        raise PlaybackError(f"{src}: step {i} is not a ps step")
    params, rms = step_params(model, steps, i, closed_loop.degree, src, opt.fit_margin)
    ss = single_support_tau(steps, i)
    span = fit_window(steps, i, opt.fit_margin)[:2]
    q0, qd0 = zero_dynamics_state(closed_loop, params, span[0])
    sim = HybridSimulator(model, closed_loop,
                          {DOMAIN: params.pack(), Domain.PNS: gait.theta(Domain.PNS)},
                          gait.gains_array, opt.sim_options())
    T = (span[1] - span[0]) * params.nominal_duration
    run = sim.run(q0, qd0, DOMAIN, steps=1, duration=math.ceil(T / opt.dt - 1e-9) * opt.dt)
    keep = run.domain == 0
    if run.impacts:  # the frame logged after the touchdown belongs to the next domain
        keep &= run.t < run.impacts[0].t
    rows = np.flatnonzero(keep)
    finite = np.all(np.isfinite(np.c_[run.q, run.qd, run.u, run.lam][rows]), axis=1)
    if not finite.all():
        rows = rows[:int(np.argmin(finite))]
    q, qd, u, lam = run.q[rows], run.qd[rows], run.u[rows], run.lam[rows]
    socket = socket_forces(model, q, qd, u, lam[:, 0:3]) if len(q) else np.zeros((0, 3))
    scale = max(float(np.abs(lam[:, 3:6]).max()) if len(q) else 0.0, 1e-12)
    kkt = float(np.abs(socket - lam[:, 3:6]).max()) / scale if len(q) else math.nan
    fz, fx = lam[:, 1], lam[:, 0]
    cone = int(np.sum((fz <= 0) | (np.abs(fx) > opt.mu * fz)))
    failed, reason = run.failed, run.reason
    if len(q) < 2 and not failed:
        failed, reason = True, "fewer than 2 frames simulated"
    return StepPlayback(
        step=i, params=params, fit_rms=rms, t=run.t[rows], tau=run.tau[rows], q=q, qd=qd, u=u,
        lam=lam, socket=socket, single_support=ss,
        kkt_residual=kkt, cone_frames=cone,
        touchdown_tau=float(sim.phase(DOMAIN, run.impacts[0].q)) if run.impacts else None,
        failed=failed, reason=reason)


# ----------------------------------------------------------------------- all steps

def playback(model: HumanProsthesisModel, gait: Gait, steps: StepsArtifact,
             n_steps: int | None = None, options: PlaybackOptions | None = None,
             progress: Progress | None = None, src: str = "steps") -> Playback:
    """Play back the first ``n_steps`` ps steps (all by default)."""
    t0 = time.perf_counter()
    check_inputs(model, gait, steps, src)
    idx = ps_steps(steps, n_steps, src)
    cl = ClosedLoop(model, gait.degree)
    out: list[StepPlayback] = []
    skipped: list[tuple[int, str]] = []
    for k, i in enumerate(idx):
        if progress is not None:
            progress(f"playback of step {i}", k, len(idx))
        sp = play_step(model, cl, gait, steps, i, options, src)
        out.append(sp)
        if sp.single_support is None:
            skipped.append((i, "no single support found by the foot-marker rule"))
        elif sp.failed:
            skipped.append((i, f"playback failed: {sp.reason}"))
    if progress is not None:
        progress("playback done", len(idx), len(idx))
    return Playback(out, skipped, time.perf_counter() - t0)


def fit_force_tube(model: HumanProsthesisModel, gait: Gait, steps: StepsArtifact,
                   tube_options: TubeOptions | None = None, n_steps: int | None = None,
                   options: PlaybackOptions | None = None, progress: Progress | None = None,
                   src: str = "steps") -> TubeResult:
    """Playback of the ps steps, their deviations from F*, the single-support interval by
    the foot-marker rule, and the certified force tube (module docstring), widened by the
    allowance of ``tube_options`` (:class:`TubeOptions`).

    With ``tube_options.model_error``, also characterise what the nominal-human model of
    ``clfqp`` does not explain along the same playbacks
    (:mod:`characterization.tube.model_error`), bounded by degree-``error_degree`` curves
    over the tube's single support in the gait's phase with the first
    ``exclude_after_touchdown`` s after touchdown excluded, stored in the tube
    (``model_error``); when those samples cannot determine a bound, the tube carries none and
    ``source["model_error"]`` says why."""
    t0 = time.perf_counter()
    to = tube_options or TubeOptions()
    degree = to.degree
    check_inputs(model, gait, steps, src)
    idx = ps_steps(steps, n_steps, src)
    if isinstance(degree, bool) or int(degree) != degree or degree < 0:
        raise PlaybackError(f"--degree must be a non-negative integer, got {degree}")
    if not 0.0 <= to.allowance < 1.0:
        raise PlaybackError(f"--allowance must be a fraction in [0, 1), got {to.allowance}")
    with_ss = [i for i in idx if single_support_tau(steps, i) is not None]
    if len(with_ss) < degree + 1:
        raise PlaybackError(
            f"{src}: {len(with_ss)} ps step(s) with single support cannot support a "
            f"degree-{degree} tube: need at least degree + 1 = {degree + 1} (use a lower "
            "--degree or more steps)")
    pb = playback(model, gait, steps, n_steps, options, progress, src)
    t1 = time.perf_counter()
    good = pb.good
    if len(good) < degree + 1:
        why = "; ".join(f"step {i}: {r}" for i, r in pb.skipped[:3])
        raise PlaybackError(f"{src}: only {len(good)} ps step(s) played back with single "
                            f"support, a degree-{degree} tube needs {degree + 1} ({why})")
    opt = options or PlaybackOptions()
    gait_ps = gait.params[DOMAIN]
    inner = [s.in_phase_of(gait_ps) for s in good] if opt.tube_phase == TubePhase.GAIT else good
    supports = {s.step: s.single_support for s in inner if s.single_support is not None}
    tau_lo, tau_hi = _tube_window(list(supports.values()), opt.tube_phase, src)
    nominal = nominal_coefficients(gait, tau_lo, tau_hi)
    profiles = deviation_profiles([s.profile for s in inner], nominal, tau_lo, tau_hi)
    peak = peak_socket_force([s.profile for s in inner], tau_lo, tau_hi)
    if progress is not None:
        progress("force-tube LPs, certificate, credibility", 0, 1)
    source = {
        "steps_file": src, "steps": [s.step for s in good],
        "skipped": [{"step": i, "reason": r} for i, r in pb.skipped],
        "playback": _playback_source(pb, opt, gait.degree),
        "single_support": {"rule": "human foot marker x moving forward (steps artifact)",
                           "phase": opt.tube_phase,
                           "per_step": {str(k): list(v) for k, v in supports.items()}},
        "allowance": {"fraction_of_peak": to.allowance, "peak_abs_F_s": peak,
                      "why": "estimation error of the playback (README: evidence on a "
                             "subject generated by the model)"},
    }
    tube = with_allowance(fit_tube(profiles, nominal, tau_lo, tau_hi, degree,
                                   gait_hash=gait.hash(), source=source, beta=to.beta),
                          to.allowance * np.asarray(peak))
    if to.model_error:
        if progress is not None:
            progress("model error of the nominal-human model", 0, 1)
        tube = with_model_error(tube, model, gait, good, to,
                                opt.tube_phase == TubePhase.GAIT, src)
    t2 = time.perf_counter()
    if progress is not None:
        progress("force tube done", 1, 1)
    return TubeResult(tube, profiles, pb, [s.step for s in good],
                      {"playback": t1 - t0, "tube": t2 - t1, "total": t2 - t0},
                      opt.tube_phase, gait_ps if opt.tube_phase == TubePhase.GAIT else None)


def _tube_window(supports: list[tuple[float, float]], phase: TubePhase, src: str
                 ) -> tuple[float, float]:
    """[tau_lo, tau_hi]: the part of single support every step shares (in the gait's phase
    within [0, 1], where the gait's F* is defined)."""
    tau_lo, tau_hi = tube_interval(supports)
    if phase == TubePhase.GAIT:  # the gait's F* is defined on its ps, tau in [0, 1]
        tau_lo, tau_hi = max(tau_lo, 0.0), min(tau_hi, 1.0)
        if not tau_hi > tau_lo:
            raise PlaybackError(f"{src}: the steps' common single support [{tau_lo:.3f}, "
                                f"{tau_hi:.3f}] in the gait's phase is empty")
    return tau_lo, tau_hi


def _playback_source(pb: Playback, opt: PlaybackOptions, bezier_degree: int
                     ) -> dict[str, object]:
    """The tube's ``source["playback"]``: how the steps were played back and how well."""
    good = pb.good
    return {
        "method": "full-model feedback linearization of each step's own Bezier fit, "
                  "F_s by eq. (Fsocket) (socket_ps)",
        "dt": opt.dt,
        "stop_at_touchdown": opt.stop_at_touchdown,
        "fit_margin": opt.fit_margin,
        "tube_phase": opt.tube_phase,
        "bezier_degree": bezier_degree,
        "max_kkt_residual": max(s.kkt_residual for s in good),
        "max_fit_rms_rad": float(max(s.fit_rms.max() for s in good)),
        "cone_frames": {str(s.step): s.cone_frames for s in good if s.cone_frames},
        "seconds": pb.seconds}


def with_model_error(tube: ForceTube, model: HumanProsthesisModel, gait: Gait,
                     steps: list[StepPlayback], options: TubeOptions | None = None,
                     within_tube: bool = True, src: str = "steps") -> ForceTube:
    """``tube`` with the model-error bound of the played-back ``steps`` (each in its own
    phase; d is evaluated at the gait's phase) of ``options``' degree, exclusion after
    touchdown and beta, over the tube's [tau_lo, tau_hi] when ``within_tube`` (the tube is
    in the gait's phase); on a failure the tube unchanged, the reason in
    ``source["model_error"]``."""
    opt = options or TubeOptions()
    samples = playback_error_samples(model, gait, steps)
    try:
        bound = fit_model_error(
            samples, error_degree_checked(opt.error_degree), opt.exclude_after_touchdown,
            (tube.tau_lo, tube.tau_hi) if within_tube else None,
            {"steps_file": src, "steps": [s.step for s in steps],
             "method_d": "nu_true from the playback's constrained dynamics (dyn_ps) minus "
                         "a + A u_p of the interaction model (model_error_ps)"}, opt.beta)
    except (TubeFitError, FitError) as e:
        return replace(tube, source={**tube.source, "model_error": f"not fitted: {e}"})
    return replace(tube, model_error=bound)


def error_degree_checked(degree: int) -> int:
    if isinstance(degree, bool) or int(degree) != degree or not 0 <= degree <= 20:
        raise PlaybackError(f"--error-degree must be an integer in [0, 20], got {degree}")
    return int(degree)


# ------------------------------------------------------------------- report, files

def report_markdown(res: TubeResult, steps_src: str = "steps", gait_src: str = "gait") -> str:
    """The Markdown report of a tube fit: inputs, per-step playback, the tube, credibility."""
    t, pb = res.tube, res.playback
    lines = [
        "# Socket-force tube", "",
        f"Steps `{steps_src}`, gait `{gait_src}` (hash `{t.gait_hash}`); "
        f"{len(pb.steps)} ps steps played back, {len(res.used)} in the tube; "
        f"degree-{t.degree} Bezier bounds on tau in [{t.tau_lo:.3f}, {t.tau_hi:.3f}] "
        "(single support by the foot-marker rule), tau = "
        + ("the gait's phase of each sample (the controllers' phase)"
           if res.phase == TubePhase.GAIT else "each step's own phase (the paper's normalization)")
        + ".", "",
        f"Time: playback {res.seconds.get('playback', 0):.2f} s, tube "
        f"{res.seconds.get('tube', 0):.2f} s.", "",
        "Each step's Bezier fit and playback window: "
        + ("every frame, tau 0 to 1 (the paper)" if t.source.get("playback", {}).get(
            "fit_margin", 0.1) is None else
           f"its single support widened by {t.source['playback']['fit_margin']:g} in tau")
        + "; F_s by eq. (Fsocket) at 1 kHz.", "",
        "## Playback", "",
        "| step | fit RMS (deg, max) | v_hip (m/s) | single support (step's tau) "
        "| F_s vs KKT (rel) "
        "| frames outside cone | status |",
        "|---|---|---|---|---|---|---|"]
    skipped = dict(pb.skipped)
    for s in pb.steps:
        ss = ("-" if s.single_support is None
              else f"{s.single_support[0]:.3f} - {s.single_support[1]:.3f}")
        lines.append(f"| {s.step} | {np.degrees(s.fit_rms.max()):.2f} | {s.params.v_hip:.3f} "
                     f"| {ss} | {s.kkt_residual:.1e} | {s.cone_frames} | "
                     f"{skipped.get(s.step, 'used')} |")
    lo, hi = t.delta_bounds(np.linspace(t.tau_lo, t.tau_hi, 201))
    lines += ["", "## Tube", "",
              "| component | lower min | upper max | mean width | unit |", "|---|---|---|---|---|"]
    for c, (name, unit) in enumerate(zip(COMPONENTS, ("N", "N", "N m"), strict=True)):
        lines.append(f"| {name} | {lo[:, c].min():.2f} | {hi[:, c].max():.2f} | "
                     f"{np.mean(hi[:, c] - lo[:, c]):.2f} | {unit} |")
    lines += ["", "The bounds above include the estimation allowance of "
              + ", ".join(f"{a:.2f} {u}" for a, u in zip(t.allowance, ("N", "N", "N m"),
                                                        strict=True))
              + f" ({100 * t.source.get('allowance', {}).get('fraction_of_peak', 0):g} % of "
              "each component's peak |F_s|), "
              "added to the certified LP bounds of the estimated profiles."]
    cert = t.credibility.get("certificate", {})
    lines += ["", f"Certificate: every sample inside: {cert.get('inside')}; optimal (KKT): "
              f"{cert.get('optimal')}; tight: {cert.get('tight')}.", "",
              credibility_markdown(t.credibility)]
    if t.model_error is not None:
        lines += ["", model_error_markdown(t.model_error)]
    elif "model_error" in t.source:
        lines += ["", f"Model error of the nominal-human model: {t.source['model_error']}."]
    return "\n".join(lines)


def output_paths(out: str | Path) -> dict[str, Path]:
    """Where ``write_outputs`` puts the tube, the Fig. 5 figure and the report."""
    p = Path(out)
    return {"tube": p, "figure": p.with_name(p.stem + "_fig5.png"),
            "report": p.with_name(p.stem + ".md")}


def write_outputs(out: str | Path, res: TubeResult, steps_src: str = "steps",
                  gait_src: str = "gait") -> dict[str, Path]:
    """Write the figure and the report next to the tube, then the tube (all atomically)."""
    return write_tube_files(out, res.tube, res.profiles,
                            report_markdown(res, steps_src, gait_src))


def write_tube_files(out: str | Path, tube: ForceTube, profiles: list[Profile], report: str
                     ) -> dict[str, Path]:
    """The Fig. 5 figure of ``profiles`` and the ``report`` next to the tube file ``out``,
    then the tube (all atomically); their paths (:func:`output_paths`)."""
    paths = output_paths(out)
    save_tube_figure(paths["figure"], tube, profiles)
    atomic_write_text(paths["report"], report + "\n")
    save_tube(paths["tube"], tube)
    return paths
