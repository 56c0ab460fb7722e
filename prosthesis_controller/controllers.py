"""The prosthesis controllers: robust CLF-QP (relaxed and exact), joint PD, robust-passive,
and the shared swing controller.  See ``README.md`` in this package for the laws, the
phase conventions and the fallbacks.

Per tick every controller: validates the measurement (a fault -> the previous torque
rate-limited toward zero), updates the domain (hysteresis on contact and foot load, minimum
dwell), runs its stance law in ``ps`` or the shared swing law in ``pns``, and clamps the
torque to the motor limits.  Model terms come from one generated-C call per tick.
"""

from __future__ import annotations

import math

import numpy as np
import piqp

from hp_model import bezier
from hp_model.compiled import CompileBackend
from hp_model.domains import DOMAINS
from hp_model.force_tube import ForceTube
from hp_model.gait_artifact import Gait
from hp_model.human_prosthesis import HumanProsthesisModel
from hp_model.outputs import HipProgress
from hp_model.prosthesis import ProsthesisSubsystem
from prosthesis_controller.clf import ResClf, res_clf
from prosthesis_controller.config import ControllerConfig
from prosthesis_controller.interface import (
    Active,
    ControllerMode,
    ControllerName,
    ControlOutput,
    Diagnostics,
    QpOutcome,
)
from prosthesis_controller.measurement import Fault, ProsthesisMeasurement, read
from prosthesis_controller.polish import polish
from prosthesis_controller.terms import LOOP_RHO_UNIT, LOOP_SIGMA_UNIT, ControllerTerms

PITCH_DEGREE = 5
FEEDFORWARD_DEGREE = 9  # phase-PD nominal torque: fit RMS ~0.01 N m motor on the demo gait
_INF = math.inf
_SOLVED = piqp.PIQP_SOLVED
_DUAL_TOL = 1e-7  # a multiplier above this (normalised problem) marks an active constraint
_SLACK_TOL = 1e-4  # second polishing guess: constraints this close (relative) are active
_ACTIVE_CLF, _ACTIVE_RHO = int(Active.CLF), int(Active.RHO_MAX)
_ACTIVE_KL, _ACTIVE_KU = int(Active.KNEE_LOWER), int(Active.KNEE_UPPER)
_ACTIVE_AL, _ACTIVE_AU = int(Active.ANKLE_LOWER), int(Active.ANKLE_UPPER)
_ACTIVE_CLAMP = int(Active.OUTPUT_CLAMP)
_NO_ESTIMATE = ((0.0, 0.0), False, False, 0)
_tuple_new = tuple.__new__  # a NamedTuple without its Python-level __new__: all fields given
assert len(Diagnostics._fields) == 14 and len(ControlOutput._fields) == 2


def socket_pitch_fit(gait: Gait, model: HumanProsthesisModel, degree: int = PITCH_DEGREE
                     ) -> np.ndarray:
    """Bezier coefficients (1, degree+1) of the socket (prosthesis top link) pitch over the
    pns phase t / T_pns, fitted to the gait's pns collocation trajectory; zeros (upright)
    when the gait carries no trajectory."""
    tr = gait.trajectory.get("pns") if gait.trajectory else None
    if not tr or "q" not in tr or "t" not in tr:
        return np.zeros((1, degree + 1))
    q, t = np.asarray(tr["q"]), np.asarray(tr["t"], dtype=float)
    if t[-1] <= t[0]:
        return np.zeros((1, degree + 1))
    pitch = model.pitch_row("socket") @ q  # what the IMU reads (the same row as the plant's)
    s = (t - t[0]) / (t[-1] - t[0])
    if len(s) <= degree:
        return np.full((1, degree + 1), pitch.mean())
    coef, *_ = np.linalg.lstsq(bezier.basis(degree, s), pitch, rcond=None)
    return coef[None, :]


def thigh_phase_table(pitch: np.ndarray, window: tuple[float, float], min_span: float = 0.2,
                      min_slope: float = 0.0, n: int = 401
                      ) -> tuple[np.ndarray, np.ndarray] | None:
    """(pitch ascending, swing phase) for ``np.interp``: the part inside ``window`` of the
    longest branch on which the nominal pns socket pitch (Bezier ``pitch`` over t / T_pns)
    falls strictly (the thigh swinging forward), narrowed to the longest stretch where the
    slope |d pitch / d s| is at least ``min_slope`` times its steepest value there (a pitch
    offset of delta rad reads as a phase error delta / |slope|: the flat ends mislead);
    None when the result spans less than ``min_span`` of the phase."""
    s = np.linspace(0.0, 1.0, n)
    p = bezier.evaluate(np.asarray(pitch, float).reshape(1, -1), s).ravel()
    inside = (s >= window[0]) & (s <= window[1])
    falls = np.r_[np.diff(p) < 0, False] & inside  # p falls from s[i] to s[i+1]
    a, b = _longest_run(falls)  # samples a..b, p strictly falling
    if b > a and min_slope > 0.0:
        slope = -np.diff(p[a:b + 1])  # > 0 on the branch, per sample step
        a2, b2 = _longest_run(np.r_[slope >= min_slope * slope.max(), False])
        a, b = a + a2, a + b2
    if s[b] - s[a] < min_span:
        return None
    return p[a:b + 1][::-1].copy(), s[a:b + 1][::-1].copy()


def _longest_run(flags: np.ndarray) -> tuple[int, int]:
    """(i, j) of the longest run of True in ``flags[:-1]``, as samples i..j (j = i + run
    length); (0, 0) when there is none. ``flags[-1]`` must be False."""
    best, start = (0, 0), None
    for i, f in enumerate(flags):
        if f and start is None:
            start = i
        if not f and start is not None:
            best = max(best, (start, i), key=lambda r: r[1] - r[0])
            start = None
    return best


def stance_torque_fit(gait: Gait, model: HumanProsthesisModel,
                      degree: int = FEEDFORWARD_DEGREE) -> np.ndarray:
    """Bezier coefficients (2, degree+1) of the nominal prosthesis MOTOR torques (knee, ankle)
    over the ps phase tau, least-squares fit to the gait's ps collocation trajectory; zeros
    (no feedforward) when the gait carries no trajectory."""
    tr = gait.trajectory.get("ps") if gait.trajectory else None
    if not tr or "q" not in tr or "u" not in tr:
        return np.zeros((2, degree + 1))
    q, u = np.asarray(tr["q"], dtype=float), np.asarray(tr["u"], dtype=float)
    p, r = gait.params["ps"], model.roles["ps"]
    tau = HipProgress.of(model, "ps").phase(q[r.knee], q[r.ankle], p.p_min, p.p_max)
    B = bezier.basis(degree, np.clip(tau, 0.0, 1.0))
    if len(tau) <= degree:
        return np.repeat(u[4:6].mean(axis=1, keepdims=True), degree + 1, axis=1)
    coef, *_ = np.linalg.lstsq(B, u[4:6].T, rcond=None)
    return coef.T


class ControllerContext:
    """Everything the controllers share, built once: subsystem, compiled terms, the RES-CLF,
    packed parameter vectors, limits and nominal durations.

    Raises ``ValueError`` for gamma > c3 or a tube made for another gait (``strict_tube``).
    A gait without durations gets its nominal durations (``GaitParams.nominal_duration``)."""

    def __init__(self, gait: Gait, tube: ForceTube, model: HumanProsthesisModel,
                 config: ControllerConfig | None = None, *,
                 subsystem: ProsthesisSubsystem | None = None, strict_tube: bool = True,
                 backend: CompileBackend | str = CompileBackend.AUTO) -> None:
        cfg = config or ControllerConfig()
        self.config, self.gait, self.tube, self.model = cfg, gait, tube, model
        if strict_tube and tube.gait_hash != gait.hash():
            raise ValueError(f"the tube was made for gait {tube.gait_hash}, not for this gait "
                             f"({gait.hash()}); refit the tube or pass strict_tube=False")
        sub = subsystem or ProsthesisSubsystem(model)
        self.subsystem = sub
        self.margin = _margin(tube)
        self.terms = ControllerTerms(sub, gait.degree, tube.nominal.shape[1] - 1, tube.degree,
                                     PITCH_DEGREE, backend, FEEDFORWARD_DEGREE,
                                     self.margin["margin_lower"].shape[1] - 1)
        c = cfg.clf
        self.clf: ResClf = res_clf(np.array(c.Q), np.array(c.R), c.eps)
        if c.gamma > self.clf.c3 + 1e-12:
            raise ValueError(f"gamma = {c.gamma} exceeds c3 = {self.clf.c3:.4f} "
                             "(lmin(Q)/lmax(P)); the CLF condition may be infeasible")
        lim = cfg.safety.torque_limits or tuple(float(v) for v in model.torque_limits[4:])
        self.limits = (float(lim[0]), float(lim[1]))
        self.gear = (float(sub.B[3, 0]), float(sub.B[4, 1]))

        ps, pns = gait.params["ps"], gait.params["pns"]
        alpha_pk = ps.alpha[model.roles["ps"].prosthesis_rows[0]]
        self.durations = {}
        for d in DOMAINS:
            T = float(gait.durations.get(d, 0.0)) if gait.durations else 0.0
            self.durations[d] = T if T > 0 else gait.params[d].nominal_duration
        T = self.terms
        self.clf_params = T.clf_layout.pack(
            alpha_pk=alpha_pk, v_hip=ps.v_hip, p_min=ps.p_min, p_max=ps.p_max,
            P_eps=self.clf.P_eps, gamma_over_eps=c.gamma / c.eps, c_rho=c.c_rho,
            nominal=tube.nominal, lower=tube.widened_lower, upper=tube.widened_upper,
            tau_lo=tube.tau_lo, tau_hi=tube.tau_hi)
        self.stance_params = T.stance_layout.pack(alpha_pk=alpha_pk, p_min=ps.p_min,
                                                  p_max=ps.p_max)
        rows = list(model.roles["pns"].prosthesis_rows)
        sw = cfg.swing
        pitch = socket_pitch_fit(gait, model)
        #: the socket-pitch branch the swing's thigh lead reads (None: clock only)
        self.thigh_table = thigh_phase_table(pitch, sw.lead_window, min_slope=sw.lead_min_slope) \
            if sw.thigh_lead \
            else None
        self.swing_params = T.swing_layout.pack(
            alpha=pns.alpha[rows], pitch=pitch,
            landing_reach=sw.landing_reach, landing_start=sw.landing_start,
            landing_flatten=sw.landing_flatten)
        pp = cfg.phase_pd
        self.feedforward = stance_torque_fit(gait, model) if pp.feedforward else \
            np.zeros((2, FEEDFORWARD_DEGREE + 1))
        self.phase_pd_params = T.phase_pd_layout.pack(
            alpha_pk=alpha_pk, v_hip=ps.v_hip, p_min=ps.p_min, p_max=ps.p_max,
            feedforward=self.feedforward, kp=pp.kp, kd=pp.kd, k_vhip=pp.k_vhip)
        ct = cfg.contact
        toe, heel = foot_extent(model)
        self.clf_loop_params = T.clf_loop_layout.pack(
            theta=gait.theta("ps"), gains=gait.gains_array, P_eps=self.clf.P_eps,
            gamma_over_eps=c.gamma / c.eps, c_rho=c.c_rho,
            rho_scale=LOOP_RHO_UNIT, c_sigma=ct.c_sigma, sigma_scale=LOOP_SIGMA_UNIT,
            mu=ct.mu, f_min=ct.f_min,
            toe=ct.cop_fraction * toe, heel=ct.cop_fraction * heel, **self.margin)
        pc = cfg.passive
        self.passive_params = T.passive_layout.pack(
            alpha_pk=alpha_pk, p_min=ps.p_min, p_max=ps.p_max, lam=pc.lam, k=pc.k,
            rho_theta=pc.rho_theta, boundary=pc.boundary, theta0=T.theta0)


def foot_extent(model: HumanProsthesisModel, side: str = "p") -> tuple[float, float]:
    """(toe, heel): distances (m) of the sole's toe and heel points ahead of and behind the
    sole frame, from the model's frames."""
    frames = {f.name: f for f in model.tree.frames}
    return float(frames[f"{side}_toe"].point[0]), float(-frames[f"{side}_heel"].point[0])


def _near(v: float, i: int, xl: np.ndarray, xu: np.ndarray, fix: int) -> int:
    """-1 / +1 if v is within the slack tolerance of its lower / upper bound, else ``fix``."""
    lo, hi = xl[i], xu[i]
    if v - lo < _SLACK_TOL * (1.0 + abs(lo)):
        return -1
    if hi - v < _SLACK_TOL * (1.0 + abs(hi)):
        return 1
    return fix


def _toward(u: float, target: float, step: float) -> float:
    d = target - u
    return u + (step if d > step else -step if d < -step else d)


def _margin(tube: ForceTube) -> dict[str, object]:
    """The bound of the interaction-aware CLF row's model error d (``clf_qp_loop``'s
    parameters): the tube's ``model_error`` Bezier box over its phase range, or a zero box
    (no margin, nothing to monitor) when the tube carries none (schema 1).  Whether it
    enters the row is decided per tick (``margin_gate``, config ``uncertainty.margin``)."""
    me = tube.model_error
    if me is None:
        z = np.zeros((2, 1))
        return {"margin_lower": z, "margin_upper": z, "margin_tau_lo": 0.0,
                "margin_tau_hi": 1.0, "margin_gate": 0.0, "d_hat": np.zeros(2)}
    return {"margin_lower": me.lower, "margin_upper": me.upper, "margin_tau_lo": me.tau_lo,
            "margin_tau_hi": me.tau_hi, "margin_gate": 0.0, "d_hat": np.zeros(2)}


class BaseController:
    """Shared tick logic; subclasses provide ``_stance``.  See the module docstring."""

    name = "base"

    def __init__(self, ctx: ControllerContext) -> None:
        self.ctx = ctx
        cfg = ctx.config
        s = cfg.safety
        self._lim = ctx.limits
        self._gear = ctx.gear
        self._fb_step = float(s.fallback_rate)
        self._vargs = (tuple(s.knee_range), tuple(s.ankle_range), float(s.max_speed),
                       tuple(s.load_range))
        d = cfg.domain
        self._load_on, self._load_off, self._dwell = d.load_on, d.load_off, d.min_dwell
        self._off_hold = d.off_hold
        self._T_ps, self._T_pns = ctx.durations["ps"], ctx.durations["pns"]
        ps = ctx.gait.params["ps"]
        self._phase_args = (ctx.terms.hip.phase_function(ps.p_min, ps.p_max), ps.nominal_rate)
        num = ctx.terms.numeric
        self._clf = num["clf_qp"]
        self._clf.inputs[1][:] = ctx.clf_params
        self._clf_x = self._clf.inputs[0]
        self._o = dict(zip(self._clf.function.name_out(), self._clf.outputs, strict=True))
        self._o_tau, self._o_V, self._o_check = self._o["tau"], self._o["V"], self._o["check"]
        self._o_Gu, self._o_hu = self._o["Gu"], self._o["hu"]
        self._sref = num["stance_ref"]
        self._sref.inputs[2][:] = ctx.stance_params
        self._swing = num["swing_ref"]
        self._swing.inputs[3][:] = ctx.swing_params
        self._pd_kp = tuple(cfg.pd.kp)
        self._pd_kd = tuple(cfg.pd.kd)
        self._sw_kp, self._sw_kd = tuple(cfg.swing.kp), tuple(cfg.swing.kd)
        self._sw_grav = 1.0 if cfg.swing.gravity else 0.0
        self._thigh = ctx.thigh_table
        self._lead_db = float(cfg.swing.lead_deadband)
        self._lead_tc = float(cfg.swing.lead_time_constant)
        self.reset()

    # -- state ------------------------------------------------------------------------
    def reset(self, torque: tuple[float, float] | np.ndarray | None = None) -> None:
        """Forget all state.  ``torque``: the previous torque to assume (motor N m, clamped
        to the limits; default zero), e.g. when taking over from another controller."""
        u = (0.0, 0.0) if torque is None else (float(torque[0]), float(torque[1]))
        lk, la = self._lim
        self._u0 = min(max(u[0], -lk), lk) if math.isfinite(u[0]) else 0.0
        self._u1 = min(max(u[1], -la), la) if math.isfinite(u[1]) else 0.0
        self._domain = self.ctx.config.domain.initial
        self._t_switch: float | None = None
        self._t_unloaded: float | None = None  # since when load <= load_off with contact
        self._t_prev = -_INF
        self.fallback_count = 0
        self._lead = 0.0  # the swing's thigh lead (phase units) and the last swing tick
        self._t_lead: float | None = None
        self._reset_estimator()

    def _reset_estimator(self) -> None:
        """Model-error estimator state (controllers that have one)."""

    def _estimator_gap(self) -> None:
        """A tick without the stance law (fault, swing): no finite difference across it."""

    def _estimate(self) -> tuple[tuple[float, float], bool, bool, int]:
        """(disturbance, valid, coverage flag, coverage count) of this tick: none here."""
        return _NO_ESTIMATE

    @property
    def domain(self) -> str:
        return self._domain

    @property
    def previous_torque(self) -> np.ndarray:
        return np.array((self._u0, self._u1))

    def _update_domain(self, t: float, contact: bool, load: float) -> str:
        stance = contact and load >= self._load_on
        if contact and load <= self._load_off:
            if self._t_unloaded is None:
                self._t_unloaded = t
            unloaded = t - self._t_unloaded >= self._off_hold
        else:
            self._t_unloaded = None
            unloaded = False
        swing = (not contact) or unloaded
        if self._t_switch is None:  # first valid sample: decide at once, start the clock
            if stance:
                self._domain = "ps"
            elif (not contact) or load <= self._load_off:
                self._domain = "pns"
            self._t_switch = t
        elif t - self._t_switch >= self._dwell:
            if self._domain == "pns" and stance:
                self._domain, self._t_switch = "ps", t
            elif self._domain == "ps" and swing:
                self._domain, self._t_switch = "pns", t
                self._lead, self._t_lead = 0.0, None
        return self._domain

    # -- laws -------------------------------------------------------------------------
    def _bounds(self) -> None:
        """The torques' box of a QP controller for this tick, in ``self._xl/_xu[0:2]``:
        max(-u_max, u_prev - du) <= u <= min(u_max, u_prev + du) (``self._qlim``,
        ``self._du``; infinite when the QP has no such bound)."""
        du = self._du
        lk, la = self._qlim
        xl, xu = self._xl, self._xu
        a, b = self._u0 - du, self._u0 + du
        xl[0] = -lk if a < -lk else a
        xu[0] = lk if b > lk else b
        a, b = self._u1 - du, self._u1 + du
        xl[1] = -la if a < -la else a
        xu[1] = la if b > la else b

    def _clf_terms(self, qk: float, qa: float, vk: float, va: float) -> None:
        x = self._clf_x
        x[0], x[1], x[2], x[3] = qk, qa, vk, va
        self._clf.call_inplace()

    def _stance_phase(self, qk: float, qa: float) -> tuple[float, float]:
        """The state-based phase tau(th_pk, th_pa) of the gait's ps (the phase the paper's
        trajectories are functions of; :meth:`hp_model.outputs.HipProgress.phase`) and its
        nominal rate (``GaitParams.nominal_rate``)."""
        phase, rate = self._phase_args
        return phase(qk, qa), rate

    def _pd_torque(self, t: float, qk: float, qa: float, vk: float, va: float
                   ) -> tuple[float, float]:
        """Stance PD on the nominal trajectory at the state-based phase, the reference
        velocities at the nominal phase rate (motor N m)."""
        tau, rate = self._stance_phase(qk, qa)
        f = self._sref
        f.inputs[0][0], f.inputs[1][0] = tau, rate
        f.call_inplace()
        qd, vd = f.outputs[0], f.outputs[1]
        kp, kd = self._pd_kp, self._pd_kd
        uk = kp[0] * (qd[0] - qk) + kd[0] * (vd[0] - vk)
        ua = kp[1] * (qd[1] - qa) + kd[1] * (vd[1] - va)
        return uk / self._gear[0], ua / self._gear[1]

    def _swing_phase(self, t: float, pitch: float) -> float:
        """tau_hat = (t - t_liftoff) / T_pns advanced by the thigh lead (``SwingConfig``):
        ``pitch`` is the socket IMU's world pitch (rad), NaN without one."""
        s = (t - self._t_switch) / self._T_pns  # type: ignore[operator]
        dt = 0.0 if self._t_lead is None else t - self._t_lead
        self._t_lead = t
        tab = self._thigh
        if tab is not None and tab[0][0] <= pitch <= tab[0][-1] \
                and tab[1][-1] <= s <= tab[1][0]:  # both on the branch: low-pass from 0
            s_thigh = float(np.interp(pitch, tab[0], tab[1]))
            self._lead += min(dt / self._lead_tc, 1.0) * ((s_thigh - s) - self._lead)
        lead = self._lead - self._lead_db
        return s + (lead if lead > 0.0 else 0.0)

    def _swing_torque(self, t: float, qk: float, qa: float, vk: float, va: float,
                      pitch: float = math.nan) -> tuple[float, float, float]:
        """Shared swing law: PD + gravity on the swing target (the pns Bezier rows at the
        swing phase and the landing offset, ``terms.swing_ref``), motor N m."""
        f = self._swing
        x = f.inputs[0]
        x[0], x[1], x[2], x[3] = qk, qa, vk, va
        f.inputs[1][0] = self._swing_phase(t, pitch)
        f.inputs[2][0] = 1.0 / self._T_pns
        f.call_inplace()
        qd, vd, _, g, tau_o = f.outputs
        tau = float(tau_o[0])
        kp, kd, gw = self._sw_kp, self._sw_kd, self._sw_grav
        uk = gw * g[0] + kp[0] * (qd[0] - qk) + kd[0] * (vd[0] - vk)
        ua = gw * g[1] + kp[1] * (qd[1] - qa) + kd[1] * (vd[1] - va)
        return uk / self._gear[0], ua / self._gear[1], tau

    def _stance(self, t: float, qk: float, qa: float, vk: float, va: float):
        """(u_knee, u_ankle, tau, V, rho, qp_status, active, mode) -- subclasses."""
        raise NotImplementedError

    def _fallback(self, t: float, qk: float, qa: float, vk: float, va: float
                  ) -> tuple[float, float]:
        """QP fallback: the previous torque moved by at most ``fallback_rate`` toward the
        stance PD torque."""
        self.fallback_count += 1
        pk, pa = self._pd_torque(t, qk, qa, vk, va)
        if not (math.isfinite(pk) and math.isfinite(pa)):
            pk = pa = 0.0
        return _toward(self._u0, pk, self._fb_step), _toward(self._u1, pa, self._fb_step)

    # -- the tick ---------------------------------------------------------------------
    def tick(self, meas: ProsthesisMeasurement) -> ControlOutput:
        fault, t, qk, qa, vk, va, load, contact, pitch = read(meas, self._t_prev,
                                                               *self._vargs)
        active = 0
        since = 0.0
        if fault:
            step = self._fb_step
            u0, u1 = _toward(self._u0, 0.0, step), _toward(self._u1, 0.0, step)
            self.fallback_count += 1
            tau = V = rho = 0.0
            status, mode = QpOutcome.NOT_RUN, ControllerMode.FAULT
            self._estimator_gap()
        else:
            self._t_prev = t
            if self._update_domain(t, contact, load) == "ps":
                u0, u1, tau, V, rho, status, active, mode = self._stance(t, qk, qa, vk, va)
                since = t - self._t_switch  # type: ignore[operator]
            else:
                u0, u1, tau = self._swing_torque(t, qk, qa, vk, va, pitch)
                V = rho = 0.0
                self._estimator_gap()
                status, mode = QpOutcome.NOT_RUN, ControllerMode.SWING
            if not (math.isfinite(u0) and math.isfinite(u1)):
                step = self._fb_step
                u0, u1 = _toward(self._u0, 0.0, step), _toward(self._u1, 0.0, step)
                self.fallback_count += 1
                mode = ControllerMode.FALLBACK
            if not (math.isfinite(tau) and math.isfinite(V) and math.isfinite(rho)):
                tau = V = rho = 0.0
        lk, la = self._lim
        c0 = lk if u0 > lk else -lk if u0 < -lk else u0
        c1 = la if u1 > la else -la if u1 < -la else u1
        if c0 != u0 or c1 != u1:
            active |= _ACTIVE_CLAMP
        self._u0, self._u1 = c0, c1
        est, valid, flag, count = self._estimate()
        # the same NamedTuples, built without their Python-level __new__ (~0.4 us less)
        return _tuple_new(ControlOutput, (np.array((c0, c1)), _tuple_new(
            Diagnostics, (tau, V, rho, status, active, self.fallback_count, int(fault),
                          self._domain, mode, est, valid, flag, count, since))))


class PDController(BaseController):
    """Joint PD on the nominal stance trajectory at the state-based phase."""

    name = ControllerName.PD

    def _stance(self, t, qk, qa, vk, va):
        self._clf_terms(qk, qa, vk, va)
        uk, ua = self._pd_torque(t, qk, qa, vk, va)
        return (uk, ua, float(self._o_tau[0]), float(self._o_V[0]), 0.0, QpOutcome.NOT_RUN, 0,
                ControllerMode.STANCE)


class PhasePdController(BaseController):
    """Phase-PD reference (``terms.phase_pd``): nominal torque + knee PD + hip-velocity
    feedback through the ankle, on the state-based phase.  Not one of the paper's
    controllers: the closed-loop experiments use it to show what a controller with the
    prosthesis's own measurements achieves when its feedback has the full loop's sign."""

    name = ControllerName.PHASE_PD

    def __init__(self, ctx: ControllerContext) -> None:
        super().__init__(ctx)
        self._ppd = ctx.terms.numeric["phase_pd"]
        self._ppd.inputs[1][:] = ctx.phase_pd_params

    def _stance(self, t, qk, qa, vk, va):
        self._clf_terms(qk, qa, vk, va)
        f = self._ppd
        x = f.inputs[0]
        x[0], x[1], x[2], x[3] = qk, qa, vk, va
        f.call_inplace()
        ff, fb = f.outputs[0], f.outputs[1]
        return (ff[0] + fb[0] / self._gear[0], ff[1] + fb[1] / self._gear[1],
                float(f.outputs[2][0]), float(self._o_V[0]), 0.0, QpOutcome.NOT_RUN, 0,
                ControllerMode.STANCE)


class PassiveController(BaseController):
    """Spong's robust passivity-based law (stand-in for Azimi et al. 2017)."""

    name = ControllerName.PASSIVE

    def __init__(self, ctx: ControllerContext) -> None:
        super().__init__(ctx)
        self._pas = ctx.terms.numeric["passive"]
        self._pas.inputs[3][:] = ctx.passive_params

    def _stance(self, t, qk, qa, vk, va):
        self._clf_terms(qk, qa, vk, va)
        tau_h, rate = self._stance_phase(qk, qa)
        f = self._pas
        x = f.inputs[0]
        x[0], x[1], x[2], x[3] = qk, qa, vk, va
        f.inputs[1][0], f.inputs[2][0] = tau_h, rate
        f.call_inplace()
        uj = f.outputs[0]
        return (uj[0] / self._gear[0], uj[1] / self._gear[1], float(self._o_tau[0]),
                float(self._o_V[0]), 0.0, QpOutcome.NOT_RUN, 0, ControllerMode.STANCE)


class ClfQpController(BaseController):
    """The paper's literal robust CLF-QP (``clfqp-paper``, ``clfqp-paper-exact``) on the
    prosthesis subsystem with the socket force an exogenous input in the tube: relaxed and
    smoothed (paper eq. robust_CLF_QP_relax) or exact (eq. robust_CLF_QP), solved by piqp
    (dense; set up once, updated every tick) over
    z = (u_k, u_a[, rho]) with the torque and rate limits as box bounds, then polished
    (:mod:`prosthesis_controller.polish`)."""

    name = ControllerName.CLFQP_PAPER

    def __init__(self, ctx: ControllerContext, relaxed: bool = True) -> None:
        self.relaxed = relaxed
        c = ctx.config.clf
        lk, la = ctx.limits
        with_limits = c.limits_in_qp if relaxed else c.exact_limits_in_qp
        self._qlim = (lk, la) if with_limits else (_INF, _INF)
        self._du = float(c.delta_u) if relaxed else _INF
        n = 3 if relaxed else 2
        self._n = n
        self._rho_max = float(c.rho_max)
        self._xl = np.full(n, -_INF)  # bounds of z for the current tick
        self._xu = np.full(n, _INF)
        # the solver sees rho / rho_scale in [0, 1]: rho's range (up to 1e4) against the
        # torques' (~1) made piqp's iterations 2-6x more numerous
        self._rho_scale = self._rho_max if self._rho_max > 0 else 1.0
        if relaxed:
            self._xl[2], self._xu[2] = 0.0, self._rho_max / self._rho_scale
        self._G3 = np.zeros((1, 3), order="F")  # the relaxed row and cost in those units
        self._c3 = np.zeros(3)
        self._h3 = np.zeros(1)
        self._solver = piqp.DenseSolver()
        st = self._solver.settings
        st.eps_abs = st.eps_rel = float(c.solver_eps)
        st.eps_duality_gap_abs = st.eps_duality_gap_rel = float(c.solver_eps)
        st.verbose = False
        # (u, u) block and row of the exact QP: contiguous copies refreshed every tick
        self._P2 = np.zeros((2, 2), order="F")
        self._G2 = np.zeros((1, 2), order="F")
        xl0, xu0 = self._xl.copy(), self._xu.copy()
        xl0[:2], xu0[:2] = -1.0, 1.0
        self._solver.setup(P=np.asfortranarray(np.eye(n)), c=np.zeros(n),
                           G=np.asfortranarray(np.ones((1, n))), h_l=np.array([-_INF]),
                           h_u=np.ones(1), x_l=xl0, x_u=xu0)
        self.name = ControllerName.CLFQP_PAPER if relaxed else ControllerName.CLFQP_PAPER_EXACT
        self.qp_solution: np.ndarray | None = None  # (u_k, u_a[, rho]) of the last solve
        self._polish = bool(c.polish)
        super().__init__(ctx)
        o = self._o
        self._o_Pu, self._o_cu = o["Pu"], o["cu"]
        self._c2 = o["cu"][:2]  # a view: contiguous

    def qp_data(self) -> tuple[np.ndarray, ...]:
        """The QP of the last stance tick as the solver got it, z = (u_k, u_a[, rho /
        rho_scale]): (P, c, G, h, x_l, x_u) with min 1/2 z^T P z + c^T z, G z <= h,
        x_l <= z <= x_u (copies; for cross-checks and benchmarks).  ``qp_solution`` is in
        the same variables."""
        n = self._n
        if n == 3:
            return (np.array(self._o_Pu, order="F"), self._c3.copy(),
                    np.array(self._G3, order="F"), self._h3.copy(), self._xl.copy(),
                    self._xu.copy())
        return (np.array(self._o_Pu[:n, :n], order="F"), self._o_cu[:n].copy(),
                np.array(self._o_Gu[:, :n], order="F"), self._o_hu.copy(), self._xl.copy(),
                self._xu.copy())

    @property
    def rho_scale(self) -> float:
        """rho = rho_scale z[2] (1 for the exact QP)."""
        return self._rho_scale if self.relaxed else 1.0

    def _stance(self, t, qk, qa, vk, va):
        self.qp_solution = None
        self._clf_terms(qk, qa, vk, va)
        tau, V = float(self._o_tau[0]), float(self._o_V[0])
        if not math.isfinite(self._o_check[0]):
            uk, ua = self._fallback(t, qk, qa, vk, va)
            return uk, ua, tau, V, 0.0, QpOutcome.NONFINITE, 0, ControllerMode.FALLBACK
        self._bounds()
        xl, xu = self._xl, self._xu
        n = self._n
        # exact feasibility test of the CLF row over the box: min_box G z <= h
        Gu, hu, cu = self._o_Gu, self._o_hu, self._o_cu
        if n == 3:  # rho in units of rho_scale, the row normalised again
            sc = self._rho_scale
            G3, c3, h3 = self._G3, self._c3, self._h3
            a0, a1, a2 = float(Gu[0, 0]), float(Gu[0, 1]), float(Gu[0, 2]) * sc
            nrm = math.sqrt(a0 * a0 + a1 * a1 + a2 * a2)
            G3[0, 0], G3[0, 1], G3[0, 2] = a0 / nrm, a1 / nrm, a2 / nrm
            h3[0] = float(hu[0]) / nrm
            c3[0], c3[1], c3[2] = cu[0], cu[1], float(cu[2]) * sc
            Gu, hu, cu = G3, h3, c3
        g = Gu[0]
        lo = 0.0
        for i in range(n):
            gi = g[i]
            if gi > 0.0:
                lo += gi * xl[i]
            elif gi < 0.0:
                lo += gi * xu[i]
        h = float(hu[0])
        if lo > h + 1e-9:
            uk, ua = self._fallback(t, qk, qa, vk, va)
            return uk, ua, tau, V, 0.0, QpOutcome.INFEASIBLE, 0, ControllerMode.FALLBACK
        s = self._solver
        P = self._o_Pu
        if n == 3:
            s.update(P=P, c=cu, G=Gu, h_u=hu, x_l=xl, x_u=xu)
        else:
            P2, G2 = self._P2, self._G2
            P2[0, 0], P2[0, 1], P2[1, 0], P2[1, 1] = P[0, 0], P[0, 1], P[1, 0], P[1, 1]
            G2[0, 0], G2[0, 1] = g[0], g[1]
            s.update(P=P2, c=self._c2, G=G2, h_u=hu, x_l=xl, x_u=xu)
        if s.solve() != _SOLVED:
            uk, ua = self._fallback(t, qk, qa, vk, va)
            return uk, ua, tau, V, 0.0, QpOutcome.FAILED, 0, ControllerMode.FALLBACK
        res = s.result
        z = res.x
        uk, ua = float(z[0]), float(z[1])
        rho = float(z[2]) if self.relaxed else 0.0
        if not (math.isfinite(uk) and math.isfinite(ua) and math.isfinite(rho)):
            uk, ua = self._fallback(t, qk, qa, vk, va)
            return uk, ua, tau, V, 0.0, QpOutcome.NONFINITE, 0, ControllerMode.FALLBACK
        # active set from the solver's multipliers
        d = _DUAL_TOL
        row = res.z_u[0] > d
        zbl, zbu = res.z_bl, res.z_bu
        fk = -1 if zbl[0] > d else 1 if zbu[0] > d else 0
        fa = -1 if zbl[1] > d else 1 if zbu[1] > d else 0
        fr = (-1 if zbl[2] > d else 1 if zbu[2] > d else 0) if self.relaxed else 0
        if self._polish:
            zp = polish(P, cu, g, h, xl, xu, self.relaxed, row, fk, fa, fr)
            if zp is None:  # weakly active constraints (tiny multipliers): guess by slack
                fk, fa, fr, row = _near(uk, 0, xl, xu, fk), _near(ua, 1, xl, xu, fa), \
                    (_near(rho, 2, xl, xu, fr) if self.relaxed else 0), \
                    row or h - (g[0] * uk + g[1] * ua + (g[2] * rho if n == 3 else 0.0)) \
                    < _SLACK_TOL * (1.0 + abs(h))
                zp = polish(P, cu, g, h, xl, xu, self.relaxed, row, fk, fa, fr)
            if zp is not None:
                uk, ua = zp[0], zp[1]
                if self.relaxed:
                    rho = zp[2]
        active = _ACTIVE_CLF if row else 0
        if fk:
            active |= _ACTIVE_KL if fk < 0 else _ACTIVE_KU
        if fa:
            active |= _ACTIVE_AL if fa < 0 else _ACTIVE_AU
        if fr > 0:
            active |= _ACTIVE_RHO
        self.qp_solution = np.array((uk, ua, rho)[:n])
        if n == 3:
            rho *= self._rho_scale
        return uk, ua, tau, V, rho, QpOutcome.SOLVED, active, ControllerMode.STANCE


def make_controller(name: ControllerName | str, gait: Gait, tube: ForceTube,
                    model: HumanProsthesisModel, config: ControllerConfig | None = None, *,
                    context: ControllerContext | None = None,
                    subsystem: ProsthesisSubsystem | None = None,
                    strict_tube: bool = True) -> BaseController:
    """A controller by name: "clfqp" (the interaction-aware robust CLF-QP, relaxed; the
    default), "clfqp-exact" (its unrelaxed form), "clfqp-paper" / "clfqp-paper-exact" (the
    paper's literal formulation on the prosthesis subsystem with the socket-force tube: a
    documented negative result), "pd", "passive" or "phase-pd" (reference, not in the
    paper).  Pass ``context`` to share the compiled terms between controllers (then gait,
    tube, model and config are taken from it).  Another name is a one-line ``ValueError``
    naming the :class:`ControllerName` choices."""
    name = ControllerName(name)
    ctx = context or ControllerContext(gait, tube, model, config, subsystem=subsystem,
                                       strict_tube=strict_tube)
    if name in (ControllerName.CLFQP, ControllerName.CLFQP_EXACT):
        from prosthesis_controller.loop_clfqp import LoopClfQpController

        return LoopClfQpController(ctx, relaxed=name == ControllerName.CLFQP)
    if name == ControllerName.CLFQP_PAPER:
        return ClfQpController(ctx, relaxed=True)
    if name == ControllerName.CLFQP_PAPER_EXACT:
        return ClfQpController(ctx, relaxed=False)
    if name == ControllerName.PD:
        return PDController(ctx)
    if name == ControllerName.PHASE_PD:
        return PhasePdController(ctx)
    return PassiveController(ctx)


__all__ = [
    "BaseController",
    "ClfQpController",
    "ControllerContext",
    "Fault",
    "PDController",
    "PassiveController",
    "PhasePdController",
    "make_controller",
    "socket_pitch_fit",
    "stance_torque_fit",
]
