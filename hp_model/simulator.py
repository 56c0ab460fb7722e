"""The one hybrid simulator: RK4 integration, event location, impacts, domain switches.

Gait verification, socket-force playback and the closed-loop experiments all run on it, and
the FMU's C code implements the same algorithm around the same generated functions.

Algorithm (deterministic; ``SimOptions`` names the numbers):

- Time advances in periods of ``dt`` (the prosthesis controller's rate); in each period the
  prosthesis motor torque u_p is held (zero-order hold) and ``substeps`` RK4 steps of
  h = dt / substeps integrate the closed loop of the current domain (``rk4_<mode>_<d>``).
  The first step of a period reuses the vector field the period's friction-cone check
  evaluated at its start under the torque applied (its first stage; ``rk4k_<mode>_<d>``,
  the same arithmetic), so a period costs 4 x substeps evaluations, that check's included.
  The default, one step per 1 ms period, is checked against a tight-tolerance reference by
  ``benchmarks/bench_accuracy.py`` (state error at every impact below 1e-6).
- Touchdown of the swing foot is the guard: swing sole height crossing zero downward, once
  the phase tau has passed ``guard_tau_min`` (so lift-off scuffing is not a touchdown), or
  from the domain's entry where the landing foot was already in the air before it (the toe
  domains: :meth:`hp_model.domains.DomainGraph.guard_from_entry`). When
  a step ends below the ground, the crossing is located by the Illinois (regula falsi)
  method on s in (0, 1], re-integrating one RK4 step of length s h from the step's start, to
  ``event_tol`` metres or ``event_iters`` iterations. A foot that touches down nearly
  tangentially can dip below the ground and rise again within one step: when the sole's
  vertical velocity is negative at the step's start and positive at its end (both ends above
  ground), the minimum of the cubic Hermite interpolant of its height is found (bisection of
  its derivative, :func:`dip`), the step is re-integrated to it, and if the sole is below
  ground there the crossing is located in (0, s_min] the same way. The impact map of the
  next domain gives qd+, the domain switches and the rest of the step, (1 - s) h, is
  integrated in the new domain.
- A lift-off (the multi-contact graph's heel off: a domain with no touchdown frame,
  :meth:`hp_model.domains.DomainGraph.touchdown_frame`) ends its domain at the end of the
  RK4 step at which the phase reaches 1: the next domain's constraints hold the state as it
  is (a heel leaving the ground: no impact).  On that graph a step is a heel strike (an
  impact into a double support); a foot landing flat from its heel is an impact too.
- A double support's trailing foot leaves when it would pull (the multi-contact graph): its
  toe's normal force, under the torque applied at a period's start, below
  ``min_normal_force``.  The designed double support ends with that force reaching zero as
  the leading foot lands flat; off the orbit the two drift apart by a few ms, and the
  constraint would hold the toe on the ground by pulling on it (0.4-0.7 kN for up to 38 ms
  before every contact was watched).  The leading foot is then landed flat at once: rotated
  flat about its ankle (its pitch logged, above ``max_touchdown_pitch`` a fall "landed on heel
  or toe") and the next domain's impact applied, a foot landing flat (not a step;
  :attr:`Impact.release`).  The leading contact pulling (a heel strike that starts below zero
  load) is a fall by the friction-cone check below; lifting the heel instead, back into the
  toe's single support past its tau = 1, was tried: its resting curves then pulled 0.9 kN on
  the toe.
- Flat-foot touchdown: the model's impact makes the landing foot a flat stance foot, but
  off the nominal orbit it lands with a small residual pitch, which the holonomic
  constraint would then freeze forever (a neutral mode that tilts the whole walker step
  after step).  At each impact the landing foot is therefore rotated flat about its ankle
  (the foot slap that follows a heel-first touchdown), i.e. that ankle angle changes by
  minus the foot pitch; a residual pitch above ``max_touchdown_pitch`` ends the run as a
  fall ("landed on heel or toe").  The correction is logged with the impact.
- Fall detection (checked at every period; ends the run with a :class:`hp_model.falls.Fall`:
  its :class:`~hp_model.falls.FallReason`, time, domain, phase and the numbers of the
  event; a touchdown on heel or toe is reported at the start of the next period): hip
  height below ``min_hip_height``; phase tau running backward more than ``tau_backward``;
  the stance foot (a double support's leading foot) pulling on the ground or slipping
  (normal force below ``min_normal_force`` or |F_x| > mu F_z, sustained over
  ``cone_periods`` periods; a double support's trailing foot slipping too where it carries
  more than ``trailing_slip_load`` body weights, when that is set); no touchdown by
  ``tau_max`` nor within ``late_touchdown`` s past the designed one (whichever is later:
  :func:`touchdown_limit`, from the gait tracked in the domain); the phase stalled (no
  touchdown within ``max_step_time`` s of the start or of the last impact: a walker
  standing still, with tau neither progressing nor running back, would otherwise be
  simulated forever); a non-finite state or a generalized speed
  above ``max_speed`` (the state diverging, e.g. a knee snapping through its straight
  posture: ended before it turns non-finite and poisons the logged impacts).
- A delayed human (``human_delay`` given, s): the human's feedback on its output errors
  arrives late, its internal model does not.  The feedback term v = (eps y1, kp y2 + kd dy2)
  is computed once per period, at its start, and the human's rows of it are applied
  ``round(human_delay / dt)`` periods later, held over the period, while the inverse
  dynamics that turns v into torques is evaluated continuously at the current state
  (``rk4_d<mode>_<d>`` of :meth:`hp_model.closed_loop.ClosedLoop.delayed`).  A touchdown
  restarts the pipeline: errors measured in the previous domain (other outputs) are dropped
  and the first error of the new domain is used until the delayed ones arrive (likewise at
  the start).  In mode full the prosthesis rows of v are not delayed (sampled at 1/dt).
  With a delay of 0 this is the human's feedback sampled at 1/dt (close to, not equal to,
  the continuous human).

Stepping: :meth:`HybridSimulator.start` returns a :class:`SimulationRun`, the run's mutable
state, advanced one period at a time by ``observe()`` (the state at the period's start, under
the torque held so far), ``apply(u_p)`` (the period's motor torque; logs the period's sample
and runs the fall checks) and ``advance()`` (integrates the period).
:meth:`HybridSimulator.run` is that loop with a policy: observe, policy, apply, stop at a
fall or when the steps or the duration are reached, advance.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from functools import partial

import numpy as np

from hp_model.closed_loop import ClosedLoop, ClosedLoopMode
from hp_model.domains import Domain
from hp_model.falls import Fall, FallOutcome, FallReason
from hp_model.human_prosthesis import HumanProsthesisModel

#: a prosthesis policy: (t, state) -> motor torque (2,) held over the next period (the plant
#: clamps it to the device's motor limits, ``model.torque_limits``)
Policy = Callable[[float, "SimState"], np.ndarray]

#: the gait the human tracks in each domain it enters: (domain, time s) -> its packed gait
#: theta (the person's choice, e.g. the curves at a commanded speed of a gait library;
#: called at the start and at each domain switch)
GaitSchedule = Callable[[Domain, float], np.ndarray]

#: one RK4 step from a fixed state under fixed inputs, as a function of its length (s): the
#: new state and the swing sole height (m) at its end (:meth:`HybridSimulator._rk4` bound)
StepFrom = Callable[[float], tuple[np.ndarray, float]]


@dataclass(frozen=True)
class SimOptions:
    """Integration and event settings (SI units)."""

    dt: float = 1e-3  # s, period of the prosthesis torque (and of the log)
    substeps: int = 1  # RK4 steps per period
    guard_tau_min: float = 0.6  # the guard is armed past this phase (a toe domain's: always)
    event_tol: float = 1e-10  # m, swing-sole height at the located impact
    event_iters: int = 60
    min_hip_height: float = 0.55  # m
    tau_backward: float = 0.15  # fall if tau drops this far below its running maximum
    tau_max: float = 1.3  # fall if no touchdown by this phase (or late_touchdown, if later)
    #: s: nor a touchdown this long past the domain's designed one, at its gait's hip speed
    #: (:func:`touchdown_limit`): about four standard deviations of a healthy person's step
    #: time (22-33 ms), the same time in a 0.1-s toe domain as in a 0.57-s paper domain
    late_touchdown: float = 0.12
    max_step_time: float = 3.0  # s; fall if no touchdown this long after the last (or start)
    max_speed: float = 200.0  # m/s or rad/s; fall if any |qd_i| exceeds it (diverging)
    min_normal_force: float = 0.0  # N
    mu: float = 0.8  # friction coefficient for the slip check
    cone_periods: int = 5
    #: body weights: a double support's trailing contact counts as slipping above this load
    #: (None: its slip is not watched, only its pull).  Off by default: the rigid contact
    #: holds a toe that would slide as it unloads at the end of a double support, and
    #: watched, at 0.05 BW, the held oracle on OpenSim's strides' fit and contact-pd on every
    #: fit end in that slide (F_x 1.2-2.2 F_z at 0.07-0.1 BW); at 0 even the committed
    #: cycle's full feedback linearization does (its toe below 0.06 BW).  A sliding contact
    #: (Coulomb friction, the toe leaving with F_x = mu F_z) is what would model it
    trailing_slip_load: float | None = None
    max_touchdown_pitch: float = 0.1  # rad

    def __post_init__(self) -> None:
        if not self.dt > 0 or self.substeps < 1:
            raise ValueError("dt must be positive and substeps >= 1")


@dataclass
class SimState:
    """The hybrid state at the start of a period (what a policy may look at; a prosthesis
    controller must restrict itself to the prosthesis's own measurements)."""

    t: float
    domain: Domain
    q: np.ndarray
    qd: np.ndarray
    tau: float
    lam: np.ndarray  # constraint wrenches of the current domain (foot, socket)
    steps: int  # steps so far (impacts that start one)
    #: the packed gait the human tracks in this domain now (None: the simulator's own,
    #: ``HybridSimulator.thetas``)
    theta: np.ndarray | None = None


@dataclass
class Impact:
    t: float
    into: Domain
    q: np.ndarray
    qd_minus: np.ndarray
    qd_plus: np.ndarray
    impulse: np.ndarray
    foot_pitch: float = 0.0  # rad, the landing foot's pitch removed at touchdown
    starts_step: bool = True  # a heel strike (not a foot landing flat from its heel)
    #: a foot landed flat because the trailing foot left a double support (module docstring)
    release: bool = False


@dataclass
class SimResult(FallOutcome):
    """Per-period log (arrays over periods), the impacts, and how the run ended."""

    t: np.ndarray
    q: np.ndarray  # (n, 12)
    qd: np.ndarray
    u: np.ndarray  # (n, 6) torques applied (prosthesis: motor torque)
    #: (n, k) the domain's constraint wrenches: the paper's graph: foot (world), socket F_s;
    #: a graph with domains of fewer constraints than k: NaN after them
    lam: np.ndarray
    tau: np.ndarray
    domain: np.ndarray  # (n,) Domain.code
    impacts: list[Impact] = field(default_factory=list)
    fall: Fall | None = None  # how the run ended (None: steps or duration reached)

    @property
    def steps(self) -> int:
        """Steps taken: the impacts that start one (every impact in the paper's graph)."""
        return sum(i.starts_step for i in self.impacts)

    def post_impact_states(self, into: Domain | str) -> list[tuple[np.ndarray, np.ndarray]]:
        return [(i.q, i.qd_plus) for i in self.impacts if i.into == into]


@dataclass(frozen=True)
class StepWatch:
    """What the fall checks remember of the current step: the phase's running peak
    tau_peak, the start of the step t_step (s), the periods the friction cone has been left
    (bad_cone) and the pitch (rad) of a touchdown on heel or toe in the last period (None:
    there was none)."""

    tau_peak: float
    t_step: float
    bad_cone: int
    heel_pitch: float | None
    #: (F_x, F_z) (N) of the contact that left its cone, when not the domain's first
    cone_force: tuple[float, float] | None = None
    #: the phase past which no touchdown is a fall (:func:`touchdown_limit`; None: tau_max)
    tau_limit: float | None = None


def touchdown_limit(opt: SimOptions, v_hip: float, step: float) -> float:
    """The phase past which a domain's missing touchdown is a fall: ``tau_max``, or
    ``late_touchdown`` s past the designed touchdown at the gait's hip speed v_hip (m/s)
    over its step p_max - p_min (m), whichever is later.  The FMU's C (``state_checks``)
    does the same arithmetic."""
    return max(opt.tau_max, 1.0 + opt.late_touchdown * v_hip / step)


def fall_check(opt: SimOptions, t: float, d: Domain, x: np.ndarray, tau: float,
               lam: np.ndarray, watch: StepWatch) -> Fall | None:
    """The fall at the start of a period (t s, domain d, state x, phase tau, stance wrench
    lam), if any: the checks of the module docstring, first found in the order non-finite,
    diverged, hip height, phase backward, tau_max, stalled, friction cone, heel or toe."""
    nq = x.size // 2
    q, qd = x[:nq], x[nq:]
    fx, fz = watch.cone_force or (float(lam[0]), float(lam[1]))
    if not np.isfinite(x).all():
        return Fall(FallReason.NON_FINITE, t, d, tau)
    speed = float(np.abs(qd).max())
    if speed > opt.max_speed:
        return Fall(FallReason.DIVERGED, t, d, tau, {"speed": speed, "limit": opt.max_speed})
    if q[1] < opt.min_hip_height:
        return Fall(FallReason.HIP_LOW, t, d, tau,
                    {"hip_height": q[1], "limit": opt.min_hip_height})
    if tau < watch.tau_peak - opt.tau_backward:
        return Fall(FallReason.PHASE_BACKWARD, t, d, tau,
                    {"tau_peak": watch.tau_peak, "limit": opt.tau_backward})
    tau_limit = opt.tau_max if watch.tau_limit is None else watch.tau_limit
    if tau > tau_limit:
        return Fall(FallReason.NO_TOUCHDOWN, t, d, tau, {"limit": tau_limit})
    if t - watch.t_step > opt.max_step_time:
        return Fall(FallReason.PHASE_STALLED, t, d, tau,
                    {"step_time": t - watch.t_step, "limit": opt.max_step_time})
    if watch.bad_cone >= opt.cone_periods:
        return Fall(FallReason.FRICTION_CONE, t, d, tau,
                    {"F_x": fx, "F_z": fz, "mu": opt.mu, "periods": watch.bad_cone})
    if watch.heel_pitch is not None:
        return Fall(FallReason.HEEL_OR_TOE, t, d, tau,
                    {"pitch": watch.heel_pitch, "limit": opt.max_touchdown_pitch})
    return None


def dip(z0: float, z1: float, m0: float, m1: float) -> float | None:
    """The minimum s in (0, 1) of the cubic Hermite interpolant of values z0, z1 and slopes
    m0 < 0 < m1 (per unit s) at s = 0, 1, by 60 bisections of its derivative; None unless
    m0 < 0 < m1.  The FMU's C (``dip`` in hpfmu_core.inc) does the same arithmetic."""
    if not (m0 < 0 and m1 > 0):
        return None
    lo, hi = 0.0, 1.0
    for _ in range(60):
        s = (lo + hi) / 2
        dp = ((6 * s * s - 6 * s) * z0 + (3 * s * s - 4 * s + 1) * m0
              + (6 * s - 6 * s * s) * z1 + (3 * s * s - 2 * s) * m1)
        if dp < 0:
            lo = s
        else:
            hi = s
    return (lo + hi) / 2


class HybridSimulator:
    """Simulates the 12-DOF model under the human's (and optionally the prosthesis's)
    feedback linearization; see the module docstring.

    ``thetas`` are the packed gait parameters per domain the human side tracks (the nominal
    gait, or a perturbed one); ``gains`` = (eps, kp, kd).  Without a prosthesis policy the
    prosthesis torques also come from feedback linearization (mode "full").
    ``human_delay`` (s): None for the continuous human, else the delayed human of the module
    docstring.  The configuration of runs: :meth:`start` (one period at a time) and
    :meth:`run` keep the state of a run out of it.
    """

    def __init__(self, model: HumanProsthesisModel, closed_loop: ClosedLoop,
                 thetas: Mapping[Domain, np.ndarray], gains: np.ndarray,
                 options: SimOptions | None = None, human_delay: float | None = None
                 ) -> None:
        if closed_loop.model is not model:
            raise ValueError("closed_loop was built for another model")
        if human_delay is not None and not (np.isfinite(human_delay) and human_delay >= 0):
            raise ValueError(f"human_delay must be finite and >= 0 s, got {human_delay}")
        self.human_delay = human_delay
        self.model, self.cl = model, closed_loop
        self._u_limit = np.asarray(model.torque_limits[4:6], dtype=float)  # motor N m
        self.thetas = {d: np.asarray(thetas[Domain(d)], dtype=float) for d in model.domains}
        self.gains = np.asarray(gains, dtype=float)
        self.opt = options or SimOptions()
        self.fs = closed_loop.numeric()
        self.dfs = closed_loop.delayed() if human_delay is not None else None
        self.mfs = model.numeric()
        self.nq = model.nq
        #: per domain: its touchdown guard armed from its entry (else past guard_tau_min)
        self.from_entry = {d: model.graph.guard_from_entry(d) for d in model.graph.domains}
        # the frame that lands when entering a domain is its stance sole, rotated about its
        # stance ankle (the paper's domains: a foot landing flat)
        self._landing = {d: (r.stance_frame_index, r.ankle) for d, r in model.roles.items()}
        #: the width of the logged wrenches: the most constraints of a domain
        self.lam_width = max(dom.n_constraints for dom in model.domains.values())
        #: N: a trailing contact's load above which its slip counts (``SimOptions``)
        self.trailing_slip_load = (math.inf if self.opt.trailing_slip_load is None else
                                   self.opt.trailing_slip_load * model.tree.total_mass
                                   * model.tree.gravity)

    # -- pieces ------------------------------------------------------------------------------
    def _rk4(self, mode: str, d: Domain, x: np.ndarray, u_p: np.ndarray, h: float,
             vhold: np.ndarray | None, k1: np.ndarray | None = None,
             theta: np.ndarray | None = None) -> tuple[np.ndarray, float]:
        """One RK4 step of h s: the new state and the swing sole height (m) at its end;
        ``vhold``: the delayed human's feedback held over the period (None: continuous);
        ``k1``: the vector field at x under the same inputs, if known (``rk4k``: the same
        numbers, one evaluation less; not with ``vhold``); ``theta``: the gait the human
        tracks (None: the simulator's, ``thetas[d]``)."""
        th = self.thetas[d] if theta is None else theta
        if k1 is not None:
            f = self.fs[f"rk4k_{mode}_{d}"]
            if mode == ClosedLoopMode.FULL:
                xn, z = f(x, th, self.gains, h, k1)
            else:
                xn, z = f(x, th, self.gains, u_p, h, k1)
            return xn.copy(), float(z[0])
        if vhold is not None:
            assert self.dfs is not None  # a held feedback is the delayed human's
            f = self.dfs[f"rk4_d{mode}_{d}"]
            if mode == ClosedLoopMode.FULL:
                xn, z = f(x, th, vhold, h)
            else:
                xn, z = f(x, th, vhold, u_p, h)
            return xn.copy(), float(z[0])
        f = self.fs[f"rk4_{mode}_{d}"]
        if mode == ClosedLoopMode.FULL:
            xn, z = f(x, th, self.gains, h)
        else:
            xn, z = f(x, th, self.gains, u_p, h)
        return xn.copy(), float(z[0])

    def _feedback(self, d: Domain, x: np.ndarray, theta: np.ndarray | None = None
                  ) -> np.ndarray:
        """The feedback term v (6) of the outputs at state x: (eps y1, kp y2 + kd dy2)
        (``theta`` as :meth:`_rk4`'s)."""
        th = self.thetas[d] if theta is None else theta
        y1, y2, dy2, _ = self.fs[f"outputs_{d}"](x[:self.nq], x[self.nq:], th)
        g = self.gains
        return np.r_[g[0] * y1, g[1] * y2 + g[2] * dy2]

    @staticmethod
    def _hold(mode: str, d: Domain, pipeline: deque[np.ndarray], v_now: np.ndarray
              ) -> np.ndarray:
        """The feedback held over the period: the human rows from the pipeline's oldest
        entry, in mode full the prosthesis rows of ``v_now``."""
        rows = list(d.human_outputs)
        if mode == ClosedLoopMode.FULL:
            v = v_now.copy()
            v[rows] = pipeline[0][rows]
            return v
        return pipeline[0][rows].copy()

    def _eval(self, mode: str, d: Domain | str, x: np.ndarray, u_p: np.ndarray,
              vhold: np.ndarray | None, theta: np.ndarray | None = None
              ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The vector field xdot (24), the torques u (6, N m) and the constraint wrenches
        lam (6) at state x (``theta`` as :meth:`_rk4`'s)."""
        th = self.thetas[Domain(d)] if theta is None else theta
        if vhold is not None:
            assert self.dfs is not None  # a held feedback is the delayed human's
            f = self.dfs[f"xdot_d{mode}_{d}"]
            if mode == ClosedLoopMode.FULL:
                xdot, u, lam = f(x, th, vhold)
            else:
                xdot, u, lam = f(x, th, vhold, u_p)
            return xdot.copy(), u.copy(), lam.copy()
        f = self.fs[f"xdot_{mode}_{d}"]
        if mode == ClosedLoopMode.FULL:
            xdot, u, lam = f(x, th, self.gains)
        else:
            xdot, u, lam = f(x, th, self.gains, u_p)
        return xdot.copy(), u.copy(), lam.copy()

    def phase(self, d: Domain | str, q: np.ndarray) -> float:
        """tau of q in domain d for the tracked gait (``VirtualConstraints.phase``: the same
        arithmetic as the FMU's generated ``phase_<d>``)."""
        return float(self.cl.vcs[Domain(d)].phase(q, self.thetas[d]))

    def _flatten_landing_foot(self, into: Domain, q: np.ndarray) -> float:
        """Rotate the foot that becomes the stance foot of ``into`` flat about its ankle
        (in place); returns the pitch removed (0 where the foot lands on a point, or flat
        from its heel: the multi-contact graph)."""
        if into not in self._landing:
            return 0.0
        return self._flatten(*self._landing[into], q)

    def _flatten(self, frame: int, ankle: int, q: np.ndarray) -> float:
        """Rotate the foot of sole frame index ``frame`` flat about its ankle (coordinate
        index ``ankle``), in place; returns the pitch removed (rad)."""
        pose = self.mfs["frames"](q, np.zeros(self.nq))[0]
        pitch = float(pose[2, frame])
        q[ankle] -= pitch
        return pitch

    def release_trailing(self, d: Domain, x: np.ndarray, t: float
                         ) -> tuple[np.ndarray, Impact] | None:
        """If ``d`` is a double support: the state after its trailing foot leaves and its
        leading foot lands flat (module docstring) and that landing's impact record, at
        time t (s); None in any other domain."""
        if not d.is_double_support:
            return None
        nq, into = self.nq, self.model.graph.next(d)
        leg = d.stance_leg  # the leading leg
        q = x[:nq].copy()
        pitch = self._flatten(self.model.frame_index(leg.sole_frame),
                              self.model.coord_names.index(leg.ankle), q)
        qdp, imp = self.mfs[f"impact_{into}"](q, x[nq:])
        impact = Impact(t, into, q, x[nq:].copy(), qdp.copy(), imp.copy(), pitch,
                        starts_step=False, release=True)
        return np.r_[q, qdp], impact

    def guard_height(self, d: Domain, x: np.ndarray) -> float:
        """The height (m) of the frame whose touchdown ends ``d`` at state x; 1 in a domain
        ended by a lift-off (:func:`hp_model.closed_loop.guard_height`)."""
        if self.model.domains[d].swing_frame is None:
            return 1.0
        return float(self.mfs[f"guard_{d}"](x[:self.nq], x[self.nq:])[0][0])

    def _locate(self, step: StepFrom, h: float, z0: float, z1: float, s1: float = 1.0
                ) -> tuple[float, np.ndarray]:
        """s in (0, s1] with swing height of ``step(s h)`` = 0 (Illinois method), z0 and z1
        the heights at 0 and s1."""
        a, b, fa, fb = 0.0, s1, z0, z1
        xs, side = None, 0
        s = 1.0
        for _ in range(self.opt.event_iters):
            s = (a * fb - b * fa) / (fb - fa)
            xs, z = step(s * h)
            if abs(z) <= self.opt.event_tol:
                break
            if z > 0:
                a, fa = s, z
                if side == 1:
                    fb /= 2
                side = 1
            else:
                b, fb = s, z
                if side == -1:
                    fa /= 2
                side = -1
        assert xs is not None
        return s, xs

    def _touchdown(self, d: Domain, x: np.ndarray, xn: np.ndarray, h: float, z0: float,
                   z1: float, step: StepFrom) -> tuple[float, float]:
        """(s1, z(s1)): the end of the bracket of a touchdown in the step of h s from x to xn
        (``step(h)``, domain d) whose sole heights are z0 > 0 and z1 (module docstring):
        (1, z1) if z1 <= 0, else the sole's lowest point inside the step if it is below
        ground there, else (1, z1)."""
        if z1 <= 0:
            return 1.0, z1
        g = self.mfs[f"guard_{d}"]
        nq = self.nq
        v0 = float(g(x[:nq], x[nq:])[1][0])
        v1 = float(g(xn[:nq], xn[nq:])[1][0])
        s = dip(z0, z1, h * v0, h * v1)
        if s is not None:
            zs = step(s * h)[1]
            if zs <= 0:
                return s, zs
        return 1.0, z1

    # -- runs ---------------------------------------------------------------------------------
    def start(self, q0: np.ndarray, qd0: np.ndarray, domain: Domain | str,
              mode: ClosedLoopMode | str = ClosedLoopMode.HUMAN,
              gaits: GaitSchedule | None = None) -> SimulationRun:
        """A run from (q0, qd0) in ``domain``, to be stepped one period at a time (module
        docstring).  ``mode`` "human": the prosthesis motor torque comes from
        :meth:`SimulationRun.apply`; "full": feedback linearization of all six torques.
        ``gaits``: the gait the human tracks in each domain it enters (None: ``thetas``
        throughout)."""
        return SimulationRun(self, q0, qd0, domain, mode, gaits)

    def run(self, q0: np.ndarray, qd0: np.ndarray, domain: Domain | str, *,
            steps: int | None = None,
            duration: float | None = None, policy: Policy | None = None,
            progress: Callable[[float, int], None] | None = None,
            gaits: GaitSchedule | None = None) -> SimResult:
        """Simulate from (q0, qd0) in ``domain`` until ``steps`` impacts or ``duration`` s
        (whichever comes first; at least one must be given), or a fall; ``policy`` gives the
        prosthesis motor torque of each period (None: mode full); ``gaits`` as
        :meth:`start`'s."""
        if steps is None and duration is None:
            raise ValueError("give steps or duration")
        max_steps = np.inf if steps is None else steps
        n_periods = (int(np.floor(duration / self.opt.dt + 1e-9))
                     if duration is not None and np.isfinite(duration) else None)
        r = self.start(q0, qd0, domain,
                       mode=ClosedLoopMode.FULL if policy is None else ClosedLoopMode.HUMAN,
                       gaits=gaits)
        while True:
            st = r.observe()
            fall = r.apply(None if policy is None else policy(st.t, st))
            if fall is not None or r.steps >= max_steps or \
                    (n_periods is not None and r.periods >= n_periods):
                break
            if progress is not None and r.periods % 100 == 0:
                progress(r.t, r.steps)
            r.advance()
        return r.result()


class SimulationRun:
    """One run of a :class:`HybridSimulator`, stepped one period of ``dt`` at a time:
    :meth:`observe`, :meth:`apply` (mode "human": the prosthesis motor torque; mode "full":
    None), then :meth:`advance` unless :attr:`fall` is set.  Holds the run's mutable state
    (hybrid state, log, impacts, fall-check counters, the delayed human's pipeline)."""

    def __init__(self, sim: HybridSimulator, q0: np.ndarray, qd0: np.ndarray,
                 domain: Domain | str,
                 mode: ClosedLoopMode | str = ClosedLoopMode.HUMAN,
                 gaits: GaitSchedule | None = None) -> None:
        mode = ClosedLoopMode(mode)
        if domain not in sim.model.domains:
            raise ValueError(f"unknown domain {domain!r}")
        self.sim, self.mode = sim, mode
        self.domain = Domain(domain)
        self.t = 0.0  # s, start of the current period
        self.periods = 0  # periods integrated
        self.impacts: list[Impact] = []
        self.fall: Fall | None = None
        self._x = np.r_[np.asarray(q0, float), np.asarray(qd0, float)]
        self._u_p = np.zeros(2)  # motor torque held (N m)
        self._log: tuple[list, ...] = ([], [], [], [], [], [], [])  # t q qd u lam tau d
        self._tau_peak = -np.inf
        self._t_step = 0.0  # start of the current step: the start, then the last impact
        self._bad_cone = 0
        self._heel: float | None = None  # pitch (rad) of a touchdown on heel or toe
        self._z_prev = sim.guard_height(self.domain, self._x)
        self._n_delay = (round(sim.human_delay / sim.opt.dt) if sim.human_delay is not None
                         else None)
        self._pipeline: deque[np.ndarray] = deque()
        self._vhold: np.ndarray | None = None  # the delayed human's feedback held
        self._obs: tuple[float, np.ndarray, np.ndarray] | None = None  # tau, u, lam
        #: the vector field at the period's start under the torque applied (the first RK4
        #: stage of the period; None with the delayed human)
        self._k1: np.ndarray | None = None
        self._applied = False
        self._lam = np.zeros(0)  # the constraint wrenches under the torque applied
        #: the gait the human tracks per domain (its last entry's, from ``gaits``)
        self.thetas = dict(sim.thetas)
        self._gaits = gaits
        #: tau of a state x (q first) per domain, for the gait tracked
        self._phase = {dd: sim.cl.vcs[dd].phase_function(sim.thetas[dd])
                       for dd in sim.model.graph.domains}
        self._tau_limit = sim.opt.tau_max  # the current domain's (:meth:`_limit`)
        self._track(self.domain, 0.0)

    @property
    def steps(self) -> int:
        """Steps so far: the impacts that start one (:attr:`SimResult.steps`)."""
        return sum(i.starts_step for i in self.impacts)

    def _track(self, d: Domain, t: float) -> None:
        """Entering ``d`` in the period that starts at t s: the gait the human tracks there
        from the schedule at t (sampled at the period's start, as the FMU's master sets it
        before each step: the same walk either way), if any (ValueError when it is not one
        of ``d``'s packed gaits)."""
        if self._gaits is None:
            self._tau_limit = self._limit(d)
            return
        th = np.asarray(self._gaits(d, t), dtype=float)
        if th.shape != self.sim.thetas[d].shape:
            raise ValueError(f"the gait schedule gave {d} at t = {t:.3f} s a gait of shape "
                             f"{th.shape}, not {self.sim.thetas[d].shape}")
        if not np.all(np.isfinite(th)):
            raise ValueError(f"the gait schedule gave {d} at t = {t:.3f} s a gait with "
                             "non-finite entries")
        self.thetas[d] = th
        self._phase[d] = self.sim.cl.vcs[d].phase_function(th)
        self._tau_limit = self._limit(d)

    def _limit(self, d: Domain) -> float:
        """The phase past which no touchdown in ``d`` is a fall, for the gait tracked."""
        _, v_hip, p_min, p_max = self.sim.cl.vcs[d].layout.unpack(self.thetas[d])
        return touchdown_limit(self.sim.opt, float(v_hip), float(p_max - p_min))

    def observe(self) -> SimState:
        """The state at the start of the current period, with the constraint wrenches under
        the torque held so far (the delayed human's pipeline takes this period's error;
        observing again in the same period returns the same state)."""
        x, nq = self._x, self.sim.nq
        tau, _, lam = self._evaluate()
        return SimState(self.t, self.domain, x[:nq].copy(), x[nq:].copy(), tau, lam.copy(),
                        self.steps, self.thetas[self.domain])

    def _evaluate(self) -> tuple[float, np.ndarray, np.ndarray]:
        """(tau, u, lam) at the start of the period under the torque held so far, evaluated
        once per period (the delayed human's pipeline takes this period's error)."""
        if self._obs is None:
            sim, x, d = self.sim, self._x, self.domain
            tau = self._phase[d](x)
            if self._n_delay is not None:  # the delayed human (module docstring)
                v_now = sim._feedback(d, x, self.thetas[d])
                self._pipeline.append(v_now)
                while len(self._pipeline) > self._n_delay + 1:
                    self._pipeline.popleft()
                self._vhold = sim._hold(self.mode, d, self._pipeline, v_now)
            xdot, u, lam = sim._eval(self.mode, d, x, self._u_p, self._vhold, self.thetas[d])
            self._obs = (tau, u, lam)
            self._k1 = xdot if self._n_delay is None else None
        return self._obs

    def apply(self, u_p: np.ndarray | None) -> Fall | None:
        """Hold the prosthesis motor torque ``u_p`` (2, N m; clamped to the device's limits,
        ``model.torque_limits[4:6]``) over this period (mode full: None), log the period's
        sample and run the fall checks: the fall, or None."""
        if self.fall is not None:
            raise RuntimeError(f"the run has ended: {self.fall.message()}")
        if self._applied:
            raise RuntimeError("apply() was already called in this period; advance() first")
        sim, x, d = self.sim, self._x, self.domain
        tau, u, lam = self._evaluate()
        if self.mode == ClosedLoopMode.HUMAN:
            if u_p is None:
                raise ValueError("mode human: give the prosthesis motor torque (2,)")
            lim = sim._u_limit  # bounded at the plant (the FMU does the same)
            self._u_p = np.minimum(np.maximum(np.asarray(u_p, dtype=float).reshape(2), -lim),
                                   lim)
            xdot, u, lam = sim._eval(self.mode, d, x, self._u_p, self._vhold, self.thetas[d])
            self._k1 = xdot if self._n_delay is None else None
        elif u_p is not None:
            raise ValueError("mode full: the torques come from feedback linearization; "
                             "apply(None)")
        self._applied = True
        self._lam = lam  # the wrenches under the torque applied
        nq = sim.nq
        logged = lam if lam.size == sim.lam_width else np.r_[
            lam, np.full(sim.lam_width - lam.size, np.nan)]
        for log, v in zip(self._log, (self.t, x[:nq].copy(), x[nq:].copy(), u, logged, tau,
                                      d.code), strict=True):
            log.append(v)
        opt = sim.opt
        self._tau_peak = max(self._tau_peak, tau)
        fz, fx = lam[1], lam[0]
        bad = fz < opt.min_normal_force or abs(fx) > opt.mu * fz
        cone_force = None
        if not bad and d.is_double_support:  # the trailing contact, where it is loaded
            k = d.contacts[0].size
            fxt, fzt = float(lam[k]), float(lam[k + 1])
            if fzt > sim.trailing_slip_load and abs(fxt) > opt.mu * fzt:
                bad, cone_force = True, (fxt, fzt)
        self._bad_cone = self._bad_cone + 1 if bad else 0
        self.fall = fall_check(opt, self.t, d, x, tau, lam,
                               StepWatch(self._tau_peak, self._t_step, self._bad_cone,
                                         self._heel, cone_force, self._tau_limit))
        return self.fall

    def advance(self) -> None:
        """Integrate the current period (``substeps`` RK4 steps with event location and
        impacts) under the torque applied; t advances by dt."""
        if self.fall is not None:
            raise RuntimeError(f"the run has ended: {self.fall.message()}")
        if not self._applied:
            raise RuntimeError("apply() the period's torque before advance()")
        sim, opt, nq, mode = self.sim, self.sim.opt, self.sim.nq, self.mode
        x, d, u_p, t = self._x, self.domain, self._u_p, self.t
        h = opt.dt / opt.substeps
        k1 = self._k1  # the field at x, the first stage of the period's first step
        trailing = d.contacts[0].size + 1  # the trailing contact's F_z in a double support
        if d.is_double_support and self._lam[trailing] < opt.min_normal_force:
            released = sim.release_trailing(d, x, t)
            assert released is not None  # a double support
            x, impact = released
            d, k1 = impact.into, None
            self._enter(d, x, impact)
        for j in range(opt.substeps):
            rest = h
            while rest > 0:
                step = partial(sim._rk4, mode, d, x, u_p, vhold=self._vhold, k1=k1,
                               theta=self.thetas[d])
                xn, z = step(rest)
                armed = (sim.model.domains[d].swing_frame is not None
                         and (sim.from_entry[d] or self._phase[d](x) >= opt.guard_tau_min))
                s1, z1 = 1.0, z
                if armed and self._z_prev > 0:
                    s1, z1 = sim._touchdown(d, x, xn, rest, self._z_prev, z, step)
                if armed and self._z_prev > 0 and z1 <= 0:
                    s, xe = sim._locate(step, rest, self._z_prev, z1, s1)
                    k1 = None
                    nxt = sim.model.graph.next(d)
                    qe, qdm = xe[:nq].copy(), xe[nq:]
                    pitch = sim._flatten_landing_foot(nxt, qe)
                    qdp, imp = sim.mfs[f"impact_{nxt}"](qe, qdm)
                    x, d = np.r_[qe, qdp], nxt
                    self._enter(d, x, Impact(t + j * h + (h - rest) + s * rest, nxt, qe,
                                             qdm.copy(), qdp.copy(), imp.copy(), pitch,
                                             nxt in sim.model.graph.step_starts))
                    rest -= s * rest
                    if rest <= 1e-15 * h:
                        break
                    continue
                x, self._z_prev = xn, z
                k1 = None
                rest = 0.0
                if sim.model.domains[d].swing_frame is None and self._phase[d](x) >= 1.0:
                    # a lift-off (a heel leaves the ground): no impact, at the step's end
                    d = sim.model.graph.next(d)
                    self._track(d, t)
                    self._z_prev = sim.guard_height(d, x)
                    self._tau_peak = -np.inf
        self._x, self.domain = x, d
        self.periods += 1
        self.t = self.periods * opt.dt
        self._obs, self._applied, self._k1 = None, False, None

    def _enter(self, d: Domain, x: np.ndarray, impact: Impact) -> None:
        """The bookkeeping of entering ``d`` at state x through ``impact``: logged, a
        touchdown on heel or toe flagged, the delayed human's pipeline restarted, the guard,
        the phase's running peak and the stall clock reset."""
        sim = self.sim
        self._track(d, self.t)
        self.impacts.append(impact)
        if abs(impact.foot_pitch) > sim.opt.max_touchdown_pitch:
            self._heel = impact.foot_pitch
        if self._n_delay is not None:  # the pipeline restarts at touchdown
            self._pipeline.clear()
            v_now = sim._feedback(d, x, self.thetas[d])
            self._pipeline.append(v_now)
            self._vhold = sim._hold(self.mode, d, self._pipeline, v_now)
        self._z_prev = sim.guard_height(d, x)
        self._tau_peak = -np.inf
        self._t_step = impact.t

    def last_sample(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(q, qd, u, lam) of the last logged period (after :meth:`apply`): the state at its
        start, the torques applied (6; the prosthesis's are motor torques) and the
        constraint wrenches (foot, socket) under them."""
        _, q, qd, u, lam, _, _ = (v[-1] for v in self._log)
        return q, qd, u, lam

    def result(self) -> SimResult:
        """The log so far (one sample per applied period), the impacts and the fall."""
        t, q, qd, u, lam, tau, d = (np.array(v) for v in self._log)
        return SimResult(t=t, q=q, qd=qd, u=u, lam=lam, tau=tau, domain=d,
                         impacts=list(self.impacts), fall=self.fall)
