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
from hp_model.force_tube import ForceTube
from hp_model.gait_artifact import Gait
from hp_model.human_prosthesis import HumanProsthesisModel
from hp_model.outputs import Y2_COORDS
from hp_model.prosthesis import ProsthesisSubsystem
from prosthesis_controller.clf import ResClf, res_clf
from prosthesis_controller.config import ControllerConfig
from prosthesis_controller.interface import (
    MODE_FALLBACK,
    MODE_FAULT,
    MODE_STANCE,
    MODE_SWING,
    QP_FAILED,
    QP_INFEASIBLE,
    QP_NONFINITE,
    QP_NOT_RUN,
    QP_SOLVED,
    Active,
    ControlOutput,
    Diagnostics,
)
from prosthesis_controller.measurement import Fault, ProsthesisMeasurement, validate
from prosthesis_controller.terms import ControllerTerms

PITCH_DEGREE = 5
_INF = math.inf
_SOLVED = piqp.PIQP_SOLVED
_ACTIVE_TOL = 1e-6


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
    frames = model.numeric()["frames"]
    i = model.frame_index("socket")
    zero = np.zeros(model.nq)
    pitch = np.array([frames(q[:, k], zero)[0][2, i] for k in range(q.shape[1])])
    s = (t - t[0]) / (t[-1] - t[0])
    if len(s) <= degree:
        return np.full((1, degree + 1), pitch.mean())
    coef, *_ = np.linalg.lstsq(bezier.basis(degree, s), pitch, rcond=None)
    return coef[None, :]


class ControllerContext:
    """Everything the controllers share, built once: subsystem, compiled terms, the RES-CLF,
    packed parameter vectors, limits and nominal durations.

    Raises ``ValueError`` for gamma > c3, a tube made for another gait (``strict_tube``),
    or non-positive durations that cannot be recovered from the gait."""

    def __init__(self, gait: Gait, tube: ForceTube, model: HumanProsthesisModel,
                 config: ControllerConfig | None = None, *,
                 subsystem: ProsthesisSubsystem | None = None, strict_tube: bool = True,
                 backend: str = "auto") -> None:
        cfg = config or ControllerConfig()
        self.config, self.gait, self.tube, self.model = cfg, gait, tube, model
        if strict_tube and tube.gait_hash != gait.hash():
            raise ValueError(f"the tube was made for gait {tube.gait_hash}, not for this gait "
                             f"({gait.hash()}); refit the tube or pass strict_tube=False")
        sub = subsystem or ProsthesisSubsystem(model)
        self.subsystem = sub
        self.terms = ControllerTerms(sub, gait.degree, tube.nominal.shape[1] - 1, tube.degree,
                                     PITCH_DEGREE, backend)
        c = cfg.clf
        self.clf: ResClf = res_clf(np.array(c.Q), np.array(c.R), c.eps)
        if c.gamma > self.clf.c3 + 1e-12:
            raise ValueError(f"gamma = {c.gamma} exceeds c3 = {self.clf.c3:.4f} "
                             "(lmin(Q)/lmax(P)); the CLF condition may be infeasible")
        lim = cfg.safety.torque_limits or tuple(float(v) for v in model.torque_limits[4:])
        self.limits = (float(lim[0]), float(lim[1]))
        self.gear = (float(sub.B[3, 0]), float(sub.B[4, 1]))

        ps, pns = gait.params["ps"], gait.params["pns"]
        alpha_pk = ps.alpha[Y2_COORDS["ps"].index("th_pk")]
        self.durations = {}
        for d, p in (("ps", ps), ("pns", pns)):
            T = float(gait.durations.get(d, 0.0)) if gait.durations else 0.0
            self.durations[d] = T if T > 0 else (p.p_max - p.p_min) / p.v_hip
        T = self.terms
        self.clf_params = T.clf_layout.pack(
            alpha_pk=alpha_pk, v_hip=ps.v_hip, p_min=ps.p_min, p_max=ps.p_max,
            P_eps=self.clf.P_eps, gamma_over_eps=c.gamma / c.eps, c_rho=c.c_rho,
            nominal=tube.nominal, lower=tube.lower, upper=tube.upper, tau_lo=tube.tau_lo,
            tau_hi=tube.tau_hi)
        self.stance_params = T.stance_layout.pack(alpha_pk=alpha_pk, p_min=ps.p_min,
                                                  p_max=ps.p_max)
        rows = [Y2_COORDS["pns"].index(n) for n in ("th_pk", "th_pa")]
        self.swing_params = T.swing_layout.pack(alpha=pns.alpha[rows],
                                                pitch=socket_pitch_fit(gait, model))
        pc = cfg.passive
        self.passive_params = T.passive_layout.pack(
            alpha_pk=alpha_pk, p_min=ps.p_min, p_max=ps.p_max, lam=pc.lam, k=pc.k,
            rho_theta=pc.rho_theta, boundary=pc.boundary, theta0=T.theta0)


def _phase(t: float, t0: float, T: float) -> tuple[float, float]:
    """Time-based phase clip((t - t0) / T, 0, 1) and its rate (0 once clipped)."""
    s = (t - t0) / T
    if s <= 0.0:
        return 0.0, 0.0
    if s >= 1.0:
        return 1.0, 0.0
    return s, 1.0 / T


def _toward(u: float, target: float, step: float) -> float:
    d = target - u
    return u + (step if d > step else -step if d < -step else d)


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
        self._T_ps, self._T_pns = ctx.durations["ps"], ctx.durations["pns"]
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
        self._t_prev = -_INF
        self.fallback_count = 0

    @property
    def domain(self) -> str:
        return self._domain

    @property
    def previous_torque(self) -> np.ndarray:
        return np.array((self._u0, self._u1))

    def _update_domain(self, t: float, contact: bool, load: float) -> str:
        stance = contact and load >= self._load_on
        swing = (not contact) or load <= self._load_off
        if self._t_switch is None:  # first valid sample: decide at once, start the clock
            if stance:
                self._domain = "ps"
            elif swing:
                self._domain = "pns"
            self._t_switch = t
        elif t - self._t_switch >= self._dwell:
            if self._domain == "pns" and stance:
                self._domain, self._t_switch = "ps", t
            elif self._domain == "ps" and swing:
                self._domain, self._t_switch = "pns", t
        return self._domain

    # -- laws -------------------------------------------------------------------------
    def _clf_terms(self, qk: float, qa: float, vk: float, va: float) -> None:
        x = self._clf_x
        x[0], x[1], x[2], x[3] = qk, qa, vk, va
        self._clf.call_inplace()

    def _pd_torque(self, t: float, qk: float, qa: float, vk: float, va: float
                   ) -> tuple[float, float]:
        """Stance PD on the nominal trajectory at the time-based phase (motor N m)."""
        tau, rate = _phase(t, self._t_switch, self._T_ps)  # type: ignore[arg-type]
        f = self._sref
        f.inputs[0][0], f.inputs[1][0] = tau, rate
        f.call_inplace()
        qd, vd = f.outputs[0], f.outputs[1]
        kp, kd = self._pd_kp, self._pd_kd
        uk = kp[0] * (qd[0] - qk) + kd[0] * (vd[0] - vk)
        ua = kp[1] * (qd[1] - qa) + kd[1] * (vd[1] - va)
        return uk / self._gear[0], ua / self._gear[1]

    def _swing_torque(self, t: float, qk: float, qa: float, vk: float, va: float
                      ) -> tuple[float, float, float]:
        """Shared swing law: PD + gravity on the pns Bezier rows at tau_hat (motor N m)."""
        tau, rate = _phase(t, self._t_switch, self._T_pns)  # type: ignore[arg-type]
        f = self._swing
        x = f.inputs[0]
        x[0], x[1], x[2], x[3] = qk, qa, vk, va
        f.inputs[1][0], f.inputs[2][0] = tau, rate
        f.call_inplace()
        qd, vd, _, g = f.outputs
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
        fault = validate(meas, self._t_prev, *self._vargs)
        active = 0
        if fault:
            step = self._fb_step
            u0, u1 = _toward(self._u0, 0.0, step), _toward(self._u1, 0.0, step)
            tau = V = rho = 0.0
            status, mode = QP_NOT_RUN, MODE_FAULT
        else:
            t = float(meas.t)
            self._t_prev = t
            qk, qa = float(meas.knee_angle), float(meas.ankle_angle)
            vk, va = float(meas.knee_vel), float(meas.ankle_vel)
            if self._update_domain(t, bool(meas.contact), float(meas.foot_load)) == "ps":
                u0, u1, tau, V, rho, status, active, mode = self._stance(t, qk, qa, vk, va)
            else:
                u0, u1, tau = self._swing_torque(t, qk, qa, vk, va)
                V = rho = 0.0
                status, mode = QP_NOT_RUN, MODE_SWING
            if not (math.isfinite(u0) and math.isfinite(u1)):
                step = self._fb_step
                u0, u1 = _toward(self._u0, 0.0, step), _toward(self._u1, 0.0, step)
                self.fallback_count += 1
                mode = MODE_FALLBACK
            if not (math.isfinite(tau) and math.isfinite(V) and math.isfinite(rho)):
                tau = V = rho = 0.0
        lk, la = self._lim
        c0 = lk if u0 > lk else -lk if u0 < -lk else u0
        c1 = la if u1 > la else -la if u1 < -la else u1
        if c0 != u0 or c1 != u1:
            active |= Active.OUTPUT_CLAMP
        self._u0, self._u1 = c0, c1
        return ControlOutput(
            np.array((c0, c1)),
            Diagnostics(tau, V, rho, status, int(active), self.fallback_count, int(fault),
                        self._domain, mode))


class PDController(BaseController):
    """Joint PD on the nominal stance trajectory at the time-based phase."""

    name = "pd"

    def _stance(self, t, qk, qa, vk, va):
        self._clf_terms(qk, qa, vk, va)
        uk, ua = self._pd_torque(t, qk, qa, vk, va)
        return (uk, ua, float(self._o_tau[0]), float(self._o_V[0]), 0.0, QP_NOT_RUN, 0,
                MODE_STANCE)


class PassiveController(BaseController):
    """Spong's robust passivity-based law (stand-in for Azimi et al. 2017)."""

    name = "passive"

    def __init__(self, ctx: ControllerContext) -> None:
        super().__init__(ctx)
        self._pas = ctx.terms.numeric["passive"]
        self._pas.inputs[3][:] = ctx.passive_params

    def _stance(self, t, qk, qa, vk, va):
        self._clf_terms(qk, qa, vk, va)
        tau_h, rate = _phase(t, self._t_switch, self._T_ps)
        f = self._pas
        x = f.inputs[0]
        x[0], x[1], x[2], x[3] = qk, qa, vk, va
        f.inputs[1][0], f.inputs[2][0] = tau_h, rate
        f.call_inplace()
        uj = f.outputs[0]
        return (uj[0] / self._gear[0], uj[1] / self._gear[1], float(self._o_tau[0]),
                float(self._o_V[0]), 0.0, QP_NOT_RUN, 0, MODE_STANCE)


class ClfQpController(BaseController):
    """Robust CLF-QP, relaxed and smoothed (paper eq. robust_CLF_QP_relax) or exact (eq.
    robust_CLF_QP), solved by piqp (dense; set up once, updated every tick, in the whitened
    variables of :mod:`prosthesis_controller.terms`)."""

    name = "clfqp"

    def __init__(self, ctx: ControllerContext, relaxed: bool = True) -> None:
        self.relaxed = relaxed
        c = ctx.config.clf
        lk, la = ctx.limits
        with_limits = c.limits_in_qp if relaxed else c.exact_limits_in_qp
        self._qlim = (lk, la) if with_limits else (_INF, _INF)
        self._du = float(c.delta_u) if relaxed else _INF
        # torque rows are needed unless both bounds are infinite
        self._rows = 3 if (math.isfinite(self._du) or with_limits) else 1
        n = 3 if relaxed else 2
        self._n = n
        self._rho_max = float(c.rho_max)
        self._xl = np.zeros(n)  # u-space bounds (u_k, u_a[, rho]) of the current tick
        self._xu = np.zeros(n)
        if relaxed:
            self._xu[2] = self._rho_max
        m = self._rows
        self._hl = np.full(m, -_INF)
        self._hu = np.zeros(m)
        self._zl = np.full(n, -_INF)  # solver-variable bounds: only rho is boxed
        self._zu = np.full(n, _INF)
        if relaxed:
            self._zl[2], self._zu[2] = 0.0, self._rho_max
        self._G = np.zeros((m, n), order="F")
        self._solver = piqp.DenseSolver()
        st = self._solver.settings
        st.eps_abs = st.eps_rel = float(c.solver_eps)
        st.verbose = False
        P = np.zeros((n, n), order="F")
        P[0, 0] = P[1, 1] = 2.0
        self._G[:, :2] = np.eye(m, 2)
        self._solver.setup(P=P, c=np.zeros(n), G=self._G, h_l=self._hl, h_u=np.ones(m),
                           x_l=self._zl, x_u=self._zu)
        self.name = "clfqp" if relaxed else "clfqp-exact"
        self.qp_solution: np.ndarray | None = None  # (u_k, u_a[, rho]) of the last solve
        super().__init__(ctx)
        o = dict(zip(self._clf.function.name_out(), self._clf.outputs, strict=True))
        self._o_cw, self._o_Gw, self._o_hw = o["cw"], o["Gw"], o["hw"]
        self._o_bs, self._o_Tw = o["bs"], o["Tw"]

    def qp_data(self) -> tuple[np.ndarray, ...]:
        """The u-space QP of the last stance tick, z = (u_k, u_a[, rho]):
        (P, c, G, h, x_l, x_u) with min 1/2 z^T P z + c^T z, G z <= h, x_l <= z <= x_u
        (copies; for cross-checks with other solvers)."""
        o = self._o
        n = self._n
        return (o["Pu"][:n, :n].copy(), o["cu"][:n].copy(), o["Gu"][:, :n].copy(),
                o["hu"].copy(), self._xl.copy(), self._xu.copy())

    def _bounds(self) -> None:
        du = self._du
        lk, la = self._qlim
        xl, xu = self._xl, self._xu
        a, b = self._u0 - du, self._u0 + du
        xl[0] = -lk if a < -lk else a
        xu[0] = lk if b > lk else b
        a, b = self._u1 - du, self._u1 + du
        xl[1] = -la if a < -la else a
        xu[1] = la if b > la else b

    def _stance(self, t, qk, qa, vk, va):
        self.qp_solution = None
        self._clf_terms(qk, qa, vk, va)
        tau, V = float(self._o_tau[0]), float(self._o_V[0])
        if not math.isfinite(self._o_check[0]):
            uk, ua = self._fallback(t, qk, qa, vk, va)
            return uk, ua, tau, V, 0.0, QP_NONFINITE, 0, MODE_FALLBACK
        self._bounds()
        xl, xu = self._xl, self._xu
        # exact feasibility test of the CLF row over the box (u-space): min_box G z <= h
        Gu, hu = self._o_Gu, self._o_hu[0]
        lo = 0.0
        for i in range(self._n):
            gi = Gu[0, i]
            if gi > 0.0:
                lo += gi * xl[i]
            elif gi < 0.0:
                lo += gi * xu[i]
        if lo > hu + 1e-9:
            uk, ua = self._fallback(t, qk, qa, vk, va)
            return uk, ua, tau, V, 0.0, QP_INFEASIBLE, 0, MODE_FALLBACK
        n = self._n
        G, Gw = self._G, self._o_Gw
        hl, hu_ = self._hl, self._hu
        G[0, :] = Gw[0, :n]
        hu_[0] = self._o_hw[0]
        if self._rows == 3:
            G[1:3, :] = Gw[1:3, :n]
            s1, s2 = self._o_bs
            hl[1], hu_[1] = xl[0] * s1, xu[0] * s1
            hl[2], hu_[2] = xl[1] * s2, xu[1] * s2
        s = self._solver
        s.update(c=self._o_cw[:n] if n == 2 else self._o_cw, G=G, h_l=hl, h_u=hu_)
        if s.solve() != _SOLVED:
            uk, ua = self._fallback(t, qk, qa, vk, va)
            return uk, ua, tau, V, 0.0, QP_FAILED, 0, MODE_FALLBACK
        z = s.result.x
        T = self._o_Tw
        w0, w1 = float(z[0]), float(z[1])
        uk = T[0, 0] * w0 + T[0, 1] * w1
        ua = T[1, 0] * w0 + T[1, 1] * w1
        rho = float(z[2]) if self.relaxed else 0.0
        if not (math.isfinite(uk) and math.isfinite(ua) and math.isfinite(rho)):
            uk, ua = self._fallback(t, qk, qa, vk, va)
            return uk, ua, tau, V, 0.0, QP_NONFINITE, 0, MODE_FALLBACK
        self.qp_solution = np.array((uk, ua, rho)[:n])
        active = 0
        g0 = G[0, 0] * w0 + G[0, 1] * w1 + (G[0, 2] * rho if self.relaxed else 0.0)
        if g0 >= hu_[0] - _ACTIVE_TOL:
            active |= Active.CLF
        if self.relaxed and rho >= self._rho_max - _ACTIVE_TOL:
            active |= Active.RHO_MAX
        # torque bounds, judged in u-space against the bound scale
        tk = _ACTIVE_TOL * (1.0 + abs(uk))
        ta = _ACTIVE_TOL * (1.0 + abs(ua))
        if uk <= xl[0] + tk:
            active |= Active.KNEE_LOWER
        elif uk >= xu[0] - tk:
            active |= Active.KNEE_UPPER
        if ua <= xl[1] + ta:
            active |= Active.ANKLE_LOWER
        elif ua >= xu[1] - ta:
            active |= Active.ANKLE_UPPER
        return uk, ua, tau, V, rho, QP_SOLVED, active, MODE_STANCE


CONTROLLERS = ("clfqp", "clfqp-exact", "pd", "passive")


def make_controller(name: str, gait: Gait, tube: ForceTube, model: HumanProsthesisModel,
                    config: ControllerConfig | None = None, *,
                    context: ControllerContext | None = None,
                    subsystem: ProsthesisSubsystem | None = None,
                    strict_tube: bool = True) -> BaseController:
    """A controller by name: "clfqp" (relaxed robust CLF-QP), "clfqp-exact", "pd" or
    "passive".  Pass ``context`` to share the compiled terms between controllers (then
    gait, tube, model and config are taken from it)."""
    if name not in CONTROLLERS:
        raise ValueError(f"unknown controller '{name}'; choose one of {', '.join(CONTROLLERS)}")
    ctx = context or ControllerContext(gait, tube, model, config, subsystem=subsystem,
                                       strict_tube=strict_tube)
    if name == "clfqp":
        return ClfQpController(ctx, relaxed=True)
    if name == "clfqp-exact":
        return ClfQpController(ctx, relaxed=False)
    if name == "pd":
        return PDController(ctx)
    return PassiveController(ctx)


__all__ = [
    "CONTROLLERS",
    "BaseController",
    "ClfQpController",
    "ControllerContext",
    "Fault",
    "PDController",
    "PassiveController",
    "make_controller",
    "socket_pitch_fit",
]
