"""What every controller shares, built once per gait, tube, model and config: the compiled
terms, the RES-CLF, the packed parameter vectors of the generated calls, the torque limits
and the nominal durations (:class:`ControllerContext`).

The curves the controllers need from the gait (the swing's socket pitch, the phase-PD's
feedforward) are read from the gait artifact (``Gait.controller_curves``, fitted once by
``gait fit``), not refitted here.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from hp_model import bezier
from hp_model.compiled import CompileBackend
from hp_model.domains import PAPER_DOMAINS, Domain
from hp_model.force_tube import ForceTube
from hp_model.gait_artifact import Gait
from hp_model.human_prosthesis import HumanProsthesisModel
from hp_model.prosthesis import ProsthesisSubsystem
from prosthesis_controller.clf import ResClf, res_clf
from prosthesis_controller.config import ControllerConfig
from prosthesis_controller.terms import LOOP_RHO_UNIT, LOOP_SIGMA_UNIT, ControllerTerms


class ControllerContext:
    """Everything the controllers share, built once: subsystem, compiled terms, the RES-CLF,
    packed parameter vectors, limits (motor N m), gear ratios and nominal durations (s).

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
        pitch = gait.controller_curves.socket_pitch
        stance_torque = gait.controller_curves.stance_torque
        self.terms = ControllerTerms(sub, gait.degree, tube.nominal.shape[1] - 1, tube.degree,
                                     pitch.shape[1] - 1, backend, stance_torque.shape[1] - 1,
                                     self.margin["margin_lower"].shape[1] - 1)
        c = cfg.clf
        self.clf: ResClf = res_clf(np.array(c.Q), np.array(c.R), c.eps)
        if c.gamma > self.clf.c3 + 1e-12:
            raise ValueError(f"gamma = {c.gamma} exceeds c3 = {self.clf.c3:.4f} "
                             "(lmin(Q)/lmax(P)); the CLF condition may be infeasible")
        lim = cfg.safety.torque_limits or tuple(float(v) for v in model.torque_limits[4:])
        self.limits = (float(lim[0]), float(lim[1]))
        self.gear = (float(sub.B[3, 0]), float(sub.B[4, 1]))
        self.durations = {d: _duration(gait, d) for d in PAPER_DOMAINS}

        ps, pns = gait.params[Domain.PS], gait.params[Domain.PNS]
        alpha_pk = ps.alpha[model.roles[Domain.PS].prosthesis_rows[0]]
        T = self.terms
        self.clf_params = T.clf_layout.pack(
            alpha_pk=alpha_pk, v_hip=ps.v_hip, p_min=ps.p_min, p_max=ps.p_max,
            P_eps=self.clf.P_eps, gamma_over_eps=c.gamma / c.eps, c_rho=c.c_rho,
            nominal=tube.nominal, lower=tube.widened_lower, upper=tube.widened_upper,
            tau_lo=tube.tau_lo, tau_hi=tube.tau_hi)
        self.stance_params = T.stance_layout.pack(alpha_pk=alpha_pk, p_min=ps.p_min,
                                                  p_max=ps.p_max)
        rows = list(model.roles[Domain.PNS].prosthesis_rows)
        sw = cfg.swing
        #: the socket-pitch branch the swing's thigh lead reads (None: clock only)
        self.thigh_table = thigh_phase_table(pitch, sw.lead_window, min_slope=sw.lead_min_slope) \
            if sw.thigh_lead else None
        self.swing_params = T.swing_layout.pack(
            alpha=pns.alpha[rows], pitch=pitch,
            landing_reach=sw.landing_reach, landing_start=sw.landing_start,
            landing_flatten=sw.landing_flatten)
        pp = cfg.phase_pd
        #: the phase-PD's nominal stance motor torque (zeros with its feedforward off)
        self.feedforward = stance_torque if pp.feedforward else np.zeros_like(stance_torque)
        self.phase_pd_params = T.phase_pd_layout.pack(
            alpha_pk=alpha_pk, v_hip=ps.v_hip, p_min=ps.p_min, p_max=ps.p_max,
            feedforward=self.feedforward, kp=pp.kp, kd=pp.kd, k_vhip=pp.k_vhip)
        ct = cfg.contact
        toe, heel = foot_extent(model)
        self.clf_loop_params = T.clf_loop_layout.pack(
            theta=gait.theta(Domain.PS), gains=gait.gains_array, P_eps=self.clf.P_eps,
            gamma_over_eps=c.gamma / c.eps, c_rho=c.c_rho,
            rho_scale=LOOP_RHO_UNIT, c_sigma=ct.c_sigma, sigma_scale=LOOP_SIGMA_UNIT,
            mu=ct.mu, f_min=ct.f_min,
            toe=ct.cop_fraction * toe, heel=ct.cop_fraction * heel, **self.margin)
        pc = cfg.passive
        self.passive_params = T.passive_layout.pack(
            alpha_pk=alpha_pk, p_min=ps.p_min, p_max=ps.p_max, lam=pc.lam, k=pc.k,
            rho_theta=pc.rho_theta, boundary=pc.boundary, theta0=T.theta0)


def _duration(gait: Gait, domain: Domain) -> float:
    """The gait's duration of ``domain`` (s), or its nominal one when it has none."""
    T = float(gait.durations.get(domain, 0.0)) if gait.durations else 0.0
    return T if T > 0 else gait.params[domain].nominal_duration


def foot_extent(model: HumanProsthesisModel, side: str = "p") -> tuple[float, float]:
    """(toe, heel): distances (m) of the sole's toe and heel points ahead of and behind the
    sole frame, from the model's frames."""
    frames = {f.name: f for f in model.tree.frames}
    return float(frames[f"{side}_toe"].point[0]), float(-frames[f"{side}_heel"].point[0])


def _margin(tube: ForceTube) -> dict[str, Any]:
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
