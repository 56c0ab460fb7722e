"""The one hybrid simulator: RK4 integration, event location, impacts, domain switches.

Gait verification, socket-force playback and the closed-loop experiments all run on it, and
the FMU's C code implements the same algorithm around the same generated functions.

Algorithm (deterministic; ``SimOptions`` names the numbers):

- Time advances in periods of ``dt`` (the prosthesis controller's rate); in each period the
  prosthesis motor torque u_p is held (zero-order hold) and ``substeps`` RK4 steps of
  h = dt / substeps integrate the closed loop of the current domain (``rk4_<mode>_<d>``).
- Touchdown of the swing foot is the guard: swing sole height crossing zero downward, once
  the phase tau has passed ``guard_tau_min`` (so lift-off scuffing is not a touchdown).
  When a step ends below the ground, the crossing is located by the Illinois (regula falsi)
  method on s in (0, 1], re-integrating one RK4 step of length s h from the step's start,
  to ``event_tol`` metres or ``event_iters`` iterations.  The impact map of the next domain
  gives qd+, the domain switches and the rest of the step, (1 - s) h, is integrated in the
  new domain.
- Flat-foot touchdown: the model's impact makes the landing foot a flat stance foot, but
  off the nominal orbit it lands with a small residual pitch, which the holonomic
  constraint would then freeze forever (a neutral mode that tilts the whole walker step
  after step).  At each impact the landing foot is therefore rotated flat about its ankle
  (the foot slap that follows a heel-first touchdown), i.e. that ankle angle changes by
  minus the foot pitch; a residual pitch above ``max_touchdown_pitch`` ends the run as a
  fall ("landed on heel or toe").  The correction is logged with the impact.
- Fall detection (checked at every period; ends the run as a failure with its reason): hip
  height below ``min_hip_height``; phase tau running backward more than ``tau_backward``;
  the stance foot pulling on the ground or slipping (normal force below ``min_normal_force``
  or |F_x| > mu F_z, sustained over ``cone_periods`` periods); no touchdown by
  ``tau_max``; the phase stalled (no touchdown within ``max_step_time`` s of the start or
  of the last impact: a walker standing still, with tau neither progressing nor running
  back, would otherwise be simulated forever); a non-finite state or a generalized speed
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
"""

from __future__ import annotations

from collections import deque
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field

import numpy as np

from hp_model.closed_loop import ClosedLoop
from hp_model.domains import DOMAIN_CODE, HUMAN_OUTPUTS
from hp_model.human_prosthesis import HumanProsthesisModel

#: a prosthesis policy: (t, state) -> motor torque (2,) held over the next period (the plant
#: clamps it to the device's motor limits, ``model.torque_limits``)
Policy = Callable[[float, "SimState"], np.ndarray]


@dataclass(frozen=True)
class SimOptions:
    """Integration and event settings (SI units)."""

    dt: float = 1e-3  # s, period of the prosthesis torque (and of the log)
    substeps: int = 2  # RK4 steps per period
    guard_tau_min: float = 0.6  # the guard is armed past this phase
    event_tol: float = 1e-10  # m, swing-sole height at the located impact
    event_iters: int = 60
    min_hip_height: float = 0.55  # m
    tau_backward: float = 0.15  # fall if tau drops this far below its running maximum
    tau_max: float = 1.3  # fall if no touchdown by this phase
    max_step_time: float = 3.0  # s; fall if no touchdown this long after the last (or start)
    max_speed: float = 200.0  # m/s or rad/s; fall if any |qd_i| exceeds it (diverging)
    min_normal_force: float = 0.0  # N
    mu: float = 0.8  # friction coefficient for the slip check
    cone_periods: int = 5
    max_touchdown_pitch: float = 0.1  # rad

    def __post_init__(self) -> None:
        if not self.dt > 0 or self.substeps < 1:
            raise ValueError("dt must be positive and substeps >= 1")


@dataclass
class SimState:
    """The hybrid state at the start of a period (what a policy may look at; a prosthesis
    controller must restrict itself to the prosthesis's own measurements)."""

    t: float
    domain: str
    q: np.ndarray
    qd: np.ndarray
    tau: float
    lam: np.ndarray  # constraint wrenches of the current domain (foot, socket)
    steps: int  # impacts so far


@dataclass
class Impact:
    t: float
    into: str
    q: np.ndarray
    qd_minus: np.ndarray
    qd_plus: np.ndarray
    impulse: np.ndarray
    foot_pitch: float = 0.0  # rad, the landing foot's pitch removed at touchdown


@dataclass
class SimResult:
    """Per-period log (arrays over periods), the impacts, and how the run ended."""

    t: np.ndarray
    q: np.ndarray  # (n, 12)
    qd: np.ndarray
    u: np.ndarray  # (n, 6) torques applied (prosthesis: motor torque)
    lam: np.ndarray  # (n, 6) foot wrench (world), socket wrench F_s
    tau: np.ndarray
    domain: np.ndarray  # (n,) 0 = ps, 1 = pns
    impacts: list[Impact] = field(default_factory=list)
    failed: bool = False
    reason: str = ""

    @property
    def steps(self) -> int:
        return len(self.impacts)

    def post_impact_states(self, into: str) -> list[tuple[np.ndarray, np.ndarray]]:
        return [(i.q, i.qd_plus) for i in self.impacts if i.into == into]


class HybridSimulator:
    """Simulates the 12-DOF model under the human's (and optionally the prosthesis's)
    feedback linearization; see the module docstring.

    ``thetas`` are the packed gait parameters per domain the human side tracks (the nominal
    gait, or a perturbed one); ``gains`` = (eps, kp, kd).  With ``prosthesis_policy`` absent
    the prosthesis torques also come from feedback linearization (mode "full").
    ``human_delay`` (s): None for the continuous human, else the delayed human of the module
    docstring.
    """

    def __init__(self, model: HumanProsthesisModel, closed_loop: ClosedLoop,
                 thetas: Mapping[str, np.ndarray], gains: np.ndarray,
                 options: SimOptions | None = None, human_delay: float | None = None
                 ) -> None:
        if closed_loop.model is not model:
            raise ValueError("closed_loop was built for another model")
        if human_delay is not None and not (np.isfinite(human_delay) and human_delay >= 0):
            raise ValueError(f"human_delay must be finite and >= 0 s, got {human_delay}")
        self.human_delay = human_delay
        self._vhold: np.ndarray | None = None  # the feedback term held over the period
        self.model, self.cl = model, closed_loop
        self._u_limit = np.asarray(model.torque_limits[4:6], dtype=float)  # motor N m
        self.thetas = {d: np.asarray(thetas[d], dtype=float) for d in model.domains}
        self.gains = np.asarray(gains, dtype=float)
        self.opt = options or SimOptions()
        self.fs = closed_loop.numeric()
        self.dfs = closed_loop.delayed() if human_delay is not None else None
        self.mfs = model.numeric()
        self.nq = model.nq
        # the frame that lands when entering a domain is its stance sole, rotated about its
        # stance ankle
        self._landing = {d: (r.stance_frame_index, r.ankle) for d, r in model.roles.items()}

    # -- pieces ------------------------------------------------------------------------------
    def _rk4(self, mode: str, d: str, x: np.ndarray, u_p: np.ndarray, h: float
             ) -> tuple[np.ndarray, float]:
        if self._vhold is not None:
            f = self.dfs[f"rk4_d{mode}_{d}"]
            if mode == "full":
                xn, z = f(x, self.thetas[d], self._vhold, h)
            else:
                xn, z = f(x, self.thetas[d], self._vhold, u_p, h)
            return xn.copy(), float(z[0])
        f = self.fs[f"rk4_{mode}_{d}"]
        if mode == "full":
            xn, z = f(x, self.thetas[d], self.gains, h)
        else:
            xn, z = f(x, self.thetas[d], self.gains, u_p, h)
        return xn.copy(), float(z[0])

    def _feedback(self, d: str, x: np.ndarray) -> np.ndarray:
        """The feedback term v (6) of the outputs at state x: (eps y1, kp y2 + kd dy2)."""
        y1, y2, dy2, _ = self.fs[f"outputs_{d}"](x[:self.nq], x[self.nq:], self.thetas[d])
        g = self.gains
        return np.r_[g[0] * y1, g[1] * y2 + g[2] * dy2]

    def _hold(self, mode: str, d: str, pipeline: deque[np.ndarray], v_now: np.ndarray
              ) -> None:
        """Set the feedback held over the period: the human rows from the pipeline's
        oldest entry, in mode full the prosthesis rows of ``v_now``."""
        rows = list(HUMAN_OUTPUTS[d])
        if mode == "full":
            v = v_now.copy()
            v[rows] = pipeline[0][rows]
            self._vhold = v
        else:
            self._vhold = pipeline[0][rows].copy()

    def _eval(self, mode: str, d: str, x: np.ndarray, u_p: np.ndarray
              ) -> tuple[np.ndarray, np.ndarray]:
        if self._vhold is not None:
            f = self.dfs[f"xdot_d{mode}_{d}"]
            if mode == "full":
                _, u, lam = f(x, self.thetas[d], self._vhold)
            else:
                _, u, lam = f(x, self.thetas[d], self._vhold, u_p)
            return u.copy(), lam.copy()
        f = self.fs[f"xdot_{mode}_{d}"]
        if mode == "full":
            _, u, lam = f(x, self.thetas[d], self.gains)
        else:
            _, u, lam = f(x, self.thetas[d], self.gains, u_p)
        return u.copy(), lam.copy()

    def phase(self, d: str, q: np.ndarray) -> float:
        """tau of q in domain d for the tracked gait (``VirtualConstraints.phase``: the same
        arithmetic as the FMU's generated ``phase_<d>``)."""
        return float(self.cl.vcs[d].phase(q, self.thetas[d]))

    def _flatten_landing_foot(self, into: str, q: np.ndarray) -> float:
        """Rotate the foot that becomes the stance foot of ``into`` flat about its ankle
        (in place); returns the pitch removed."""
        frame, ankle = self._landing[into]
        pose = self.mfs["frames"](q, np.zeros(self.nq))[0]
        pitch = float(pose[2, frame])
        q[ankle] -= pitch
        return pitch

    def _locate(self, mode: str, d: str, x0: np.ndarray, u_p: np.ndarray, h: float,
                z0: float, z1: float) -> tuple[float, np.ndarray]:
        """s in (0, 1] with swing height of rk4(x0, s h) = 0 (Illinois method)."""
        a, b, fa, fb = 0.0, 1.0, z0, z1
        xs, side = None, 0
        s = 1.0
        for _ in range(self.opt.event_iters):
            s = (a * fb - b * fa) / (fb - fa)
            xs, z = self._rk4(mode, d, x0, u_p, s * h)
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

    # -- the run --------------------------------------------------------------------------------
    def run(self, q0: np.ndarray, qd0: np.ndarray, domain: str, *, steps: int | None = None,
            duration: float | None = None, policy: Policy | None = None,
            progress: Callable[[float, int], None] | None = None) -> SimResult:
        """Simulate from (q0, qd0) in ``domain`` until ``steps`` impacts or ``duration`` s
        (whichever comes first; at least one must be given), or a fall."""
        if steps is None and duration is None:
            raise ValueError("give steps or duration")
        opt, nq = self.opt, self.nq
        mode = "full" if policy is None else "human"
        t_end = np.inf if duration is None else duration
        max_steps = np.inf if steps is None else steps
        x = np.r_[np.asarray(q0, float), np.asarray(qd0, float)]
        d = domain
        t, h = 0.0, opt.dt / opt.substeps
        u_p = np.zeros(2)
        log_t, log_q, log_qd, log_u, log_lam, log_tau, log_d = [], [], [], [], [], [], []
        impacts: list[Impact] = []
        tau_peak = -np.inf
        t_step = 0.0  # start of the current step: the start, then the last impact
        bad_cone = 0
        failed, reason = False, ""
        z_prev = float(self.mfs[f"guard_{d}"](x[:nq], x[nq:])[0][0])
        n_periods = int(np.floor(t_end / opt.dt + 1e-9)) if np.isfinite(t_end) else None
        k = 0
        self._vhold = None
        pipeline: deque[np.ndarray] = deque()
        n_delay = (round(self.human_delay / opt.dt) if self.human_delay is not None
                   else None)
        while True:
            q, qd = x[:nq], x[nq:]
            tau = self.phase(d, q)
            if n_delay is not None:  # the delayed human (module docstring)
                v_now = self._feedback(d, x)
                pipeline.append(v_now)
                while len(pipeline) > n_delay + 1:
                    pipeline.popleft()
                self._hold(mode, d, pipeline, v_now)
            state_u, lam = self._eval(mode, d, x, u_p)
            if policy is not None:
                st = SimState(t, d, q.copy(), qd.copy(), tau, lam, len(impacts))
                # bounded at the plant whatever the policy computed (the FMU does the same)
                u_p = np.clip(np.asarray(policy(t, st), dtype=float).reshape(2),
                              -self._u_limit, self._u_limit)
                state_u, lam = self._eval(mode, d, x, u_p)
            log_t.append(t)
            log_q.append(q.copy())
            log_qd.append(qd.copy())
            log_u.append(state_u)
            log_lam.append(lam)
            log_tau.append(tau)
            log_d.append(DOMAIN_CODE[d])
            # fall detection
            tau_peak = max(tau_peak, tau)
            fz, fx = lam[1], lam[0]
            bad_cone = bad_cone + 1 if (fz < opt.min_normal_force or abs(fx) > opt.mu * fz) \
                else 0
            if not np.all(np.isfinite(x)):
                failed, reason = True, "non-finite state"
            elif np.max(np.abs(qd)) > opt.max_speed:
                failed, reason = True, (f"state diverged (a speed above {opt.max_speed:g} "
                                        f"m/s or rad/s)")
            elif q[1] < opt.min_hip_height:
                failed, reason = True, f"hip height {q[1]:.3f} m below {opt.min_hip_height} m"
            elif tau < tau_peak - opt.tau_backward:
                failed, reason = True, f"phase ran backward (tau {tau:.3f}, peak {tau_peak:.3f})"
            elif tau > opt.tau_max:
                failed, reason = True, f"no touchdown by tau = {opt.tau_max}"
            elif t - t_step > opt.max_step_time:
                failed, reason = True, (f"phase stalled (no touchdown within "
                                        f"{opt.max_step_time:g} s)")
            elif bad_cone >= opt.cone_periods:
                failed, reason = True, (f"stance foot left the friction cone "
                                        f"(F_x {fx:.0f} N, F_z {fz:.0f} N)")
            if failed:
                reason = f"t = {t:.3f} s, {d}, tau = {tau:.3f}: {reason}"
                break
            if len(impacts) >= max_steps or (n_periods is not None and k >= n_periods):
                break
            if progress is not None and k % 100 == 0:
                progress(t, len(impacts))
            # one period: substeps RK4 steps with event location
            for j in range(opt.substeps):
                rest = h
                while rest > 0:
                    xn, z = self._rk4(mode, d, x, u_p, rest)
                    armed = self.phase(d, x[:nq]) >= opt.guard_tau_min
                    if armed and z_prev > 0 and z <= 0:
                        s, xe = self._locate(mode, d, x, u_p, rest, z_prev, z)
                        nxt = self.model.domains[d].next
                        assert nxt is not None
                        qe, qdm = xe[:nq].copy(), xe[nq:]
                        pitch = self._flatten_landing_foot(nxt, qe)
                        qdp, imp = self.mfs[f"impact_{nxt}"](qe, qdm)
                        impacts.append(Impact(t + j * h + (h - rest) + s * rest, nxt, qe,
                                              qdm.copy(), qdp.copy(), imp.copy(), pitch))
                        if abs(pitch) > opt.max_touchdown_pitch:
                            failed, reason = True, (f"landed on heel or toe (foot pitch "
                                                    f"{pitch:.3f} rad)")
                        x = np.r_[qe, qdp]
                        d = nxt
                        if n_delay is not None:  # the pipeline restarts at touchdown
                            pipeline.clear()
                            v_now = self._feedback(d, x)
                            pipeline.append(v_now)
                            self._hold(mode, d, pipeline, v_now)
                        z_prev = float(self.mfs[f"guard_{d}"](qe, qdp)[0][0])
                        tau_peak = -np.inf
                        t_step = impacts[-1].t
                        rest -= s * rest
                        if rest <= 1e-15 * h:
                            break
                        continue
                    x, z_prev = xn, z
                    rest = 0.0
            t = (k + 1) * opt.dt
            k += 1
        self._vhold = None
        return SimResult(t=np.array(log_t), q=np.array(log_q), qd=np.array(log_qd),
                         u=np.array(log_u), lam=np.array(log_lam), tau=np.array(log_tau),
                         domain=np.array(log_d), impacts=impacts, failed=failed, reason=reason)
