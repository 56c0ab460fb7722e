"""Controller configuration: every gain and bound, with defaults that work on the default
subject and device (``hp_model.load_model()``).

Units: torques are MOTOR torques in N m (the model's ``u_p``; joint torque = gear ratio x
motor torque) unless a field says "joint"; angles rad, rates rad/s, forces N, times s.
Every model derives from :class:`hp_model.config.StrictConfig` (frozen, unknown fields
refused, so a typo in a config file is an error, never a silently ignored option; every
float finite unless typed ``PositiveOrInf``) and uses its range types.
"""

from __future__ import annotations

import numpy as np
from pydantic import Field, model_validator

from hp_model.config import NonNegative, Positive, PositiveOrInf, StrictConfig, UnitInterval
from hp_model.domains import Domain

Pair = tuple[float, float]


class ClfConfig(StrictConfig):
    """Robust CLF-QP (paper eqs. robust_CLF_QP and robust_CLF_QP_relax).

    - ``eps``: RES-CLF epsilon, 0 < eps < 1; V_eps = eta^T I_eps P I_eps eta with
      I_eps = diag(1, 1/eps, 1) and the CLF condition dV <= -(gamma/eps) V.
    - ``gamma``: decay constant, must be <= c3 = lmin(Q)/lmax(P) (checked at construction).
    - ``Q`` (3x3), ``R`` (2x2): CARE weights for the output dynamics (F, G).
    - ``rho_max``, ``c_rho``: relaxation bound (units of V, dimensionless) and its linear
      cost weight (units of the cost |nu|^2 per unit of rho).  Only the relaxed variant.
      The default rho_max keeps the QP feasible along the default subject's nominal stance
      with its fitted tube (largest rho measured 3.7e3; README).
    - ``delta_u``: rate bound |u - u_prev| per tick (motor N m), relaxed variant only
      (+inf: none).
    - ``limits_in_qp``: put the torque limits into the relaxed QP as bounds (paper: yes).
    - ``exact_limits_in_qp``: torque limits as bounds of the exact QP too (paper eq.
      robust_CLF_QP has none: off); the output is clamped to the limits either way.
    - ``solver_eps``: piqp absolute, relative and duality-gap tolerances (normalised QP).
    - ``polish``: re-solve exactly on the active set piqp reports (accepted only if it is
      the verified optimum), as OSQP's polishing does.
    - ``loop_solver_eps``: piqp tolerances of the interaction-aware QP (``clfqp``), whose
      A is well conditioned (cond 50-140) and needs no polishing; near V = 0 its CLF row is
      degenerate (LGV -> 0) and piqp stalls at 1e-10 (measured: 250 iterations), converging
      in 11-12 at 1e-8 (agreement with quadprog: tests).  A failed solve is retried once at
      100x the tolerance before the fallback.
    """

    eps: float = Field(0.02, gt=0, lt=1)
    gamma: Positive = 0.3
    Q: tuple[tuple[float, float, float], ...] = ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0),
                                                 (0.0, 0.0, 1.0))
    R: tuple[tuple[float, float], ...] = ((1.0, 0.0), (0.0, 1.0))
    rho_max: NonNegative = 1.0e4
    c_rho: NonNegative = 1.0e3
    delta_u: PositiveOrInf = 0.25
    limits_in_qp: bool = True
    exact_limits_in_qp: bool = False
    solver_eps: Positive = 1e-10
    polish: bool = True
    loop_solver_eps: Positive = 1e-8

    @model_validator(mode="after")
    def _shapes(self) -> ClfConfig:
        Q, R = np.array(self.Q, dtype=float), np.array(self.R, dtype=float)
        if Q.shape != (3, 3) or R.shape != (2, 2):
            raise ValueError(f"Q must be 3x3 and R 2x2, got {Q.shape} and {R.shape}")
        for name, M in (("Q", Q), ("R", R)):
            if not np.allclose(M, M.T) or np.linalg.eigvalsh(M).min() <= 0:
                raise ValueError(f"{name} must be symmetric positive definite")
        return self


class ContactConfig(StrictConfig):
    """Stance-foot contact rows of the interaction-aware CLF-QP (``clfqp``): the ground
    reaction w = (F_x, F_z, M_y) at the prosthesis sole, affine in the motor torque, is kept
    in the friction cone |F_x| <= ``mu`` F_z, with F_z >= ``f_min`` and its centre of pressure
    -M_y / F_z within ``cop_fraction`` of the heel and toe distances.  The rows are relaxed
    together by sigma in [0, ``sigma_max``] (torque-equivalent units, N m motor per row) at
    the linear cost ``c_sigma``: zero whenever they can hold (an exact penalty).

    ``mu`` 0.5 leaves a margin to the simulated ground's 0.8 (and the gait design's 0.6).
    ``cop_fraction`` is 1 (the whole sole) because the CoP is where the nominal-human model is
    least right: the ankle moment M_y carries the human's posture, so a human that tracks
    its outputs less stiffly or late moves the true CoP where the rows do not see it.  At
    0.8 the CoP rows were active on 59-97 % of the early-stance ticks of such a human
    (robustness sweep, tracking draw 83) and starved the CLF row until the stances
    lengthened (0.81, 0.87, 0.99 s) and the human's foot slipped; at 1.0 it walks, and the
    other 1077 walkable draws of the sweep and the demo's runs are unchanged (package README)."""

    mu: Positive = 0.5
    f_min: NonNegative = 30.0
    cop_fraction: float = Field(1.0, gt=0, le=1)
    sigma_max: Positive = 100.0
    c_sigma: Positive = 1.0e6


class UncertaintyConfig(StrictConfig):
    """The characterised model error of ``clfqp`` (the tube's ``model_error``, issue 17) and
    its online estimate.

    - ``margin`` (on by default): the bound in the robust CLF row, the worst case of d over
      it, LGV c_d + |LGV| r_d, over its phase range, from ``exclude_after_touchdown`` after
      the switch to stance on: the paper's robust term with the interaction model's error
      in place of the socket-force tube (the first 30 ms after touchdown are left to the
      relaxation).  Off: the row is the nominal model's and the bound serves the coverage
      monitor only.  A tube without a model-error bound gives no margin either way.
      Measured (demo subject, 20 steps, margin on vs off): knee RMS 0.0013 rad either
      way, perturbed cases 0.0027 / 0.0053 / 0.0036 vs 0.0028 / 0.0053 / 0.0036 rad,
      worst orbit contraction per cycle 0.81 either way; the robustness sweep's 1078
      walkable draws the same; the exact law's torque chatter 246 vs 23 N m/s (the
      paper's Fig. 6: the worst-case term is what makes the exact law chatter).
    - ``compensate`` (off by default): the online estimate enters the law.  The drift of
      the CLF row and of the cost becomes a + d_c, d_c the estimate d_hat low-passed again
      (``compensate_filter`` T_c, s), updated from ``compensate_after`` (s) after the switch
      to stance (the impact transient) and held in swing, reset with the controller: a
      disturbance observer on what the nominal-human model does not explain (a human that
      tracks its outputs less stiffly or late shifts d for whole steps).  With T_c = 5 ms
      (d_hat itself) the sensor family's velocity noise and quantization reach the law (55
      of 200 draws fell).  Off by default: on the demo subject it changes little (knee RMS
      0.0012 vs 0.0013 rad nominal, worst contraction 0.82 vs 0.81, relaxed torque
      variation 20.3 vs 16.5 N m/s) and the sweep draw it once saved walks without it
      (package README, "Compensation").
    - ``filter_time``: time constant T_f (s) of the causal first-order low-pass of the
      disturbance estimate d_hat (a finite difference of the measured joint velocities,
      compared with a + A u_prev of the previous tick): d_hat += dt / (T_f + dt) (d_raw -
      d_hat).  Its lag on a ramp of d is T_f; velocity quantization q_v (1e-4 rad/s on the
      bus) enters d_raw as about |Jv| q_v / dt per tick and leaves the filter reduced by
      sqrt(dt / (2 T_f)).
    - ``max_dt``: a tick more than this after the previous stance tick restarts the
      estimator (no finite difference across a gap, a fault or swing).
    - ``monitor_tolerance``: (dy1 [m/s^2], d2y2 [rad/s^2]) added to both sides of the bound
      before a filtered estimate counts as outside (the estimate's own noise and lag).
    """

    margin: bool = True
    compensate: bool = False
    compensate_after: float = Field(0.03, ge=0)
    compensate_filter: Positive = 0.02
    filter_time: Positive = 0.005
    max_dt: Positive = 0.005
    monitor_tolerance: Pair = (0.05, 1.0)


class PdConfig(StrictConfig):
    """Joint PD on the nominal prosthesis trajectory as a function of the state-based stance
    phase tau(th_pk, th_pa), reference velocities at the nominal phase rate (JOINT-side gains,
    N m/rad and N m s/rad; no model information, as the paper's PD).  Defaults chosen by
    :mod:`orchestrator.experiments.baseline_gains` on the default subject's nominal run (the
    walking pair of its grid with the lowest knee RMS) and frozen for every other case."""

    kp: Pair = (12000.0, 12000.0)
    kd: Pair = (150.0, 150.0)


class PhasePdConfig(StrictConfig):
    """Phase-PD reference (not one of the paper's controllers): on the CLF-QP's state-based
    phase tau(th_pk, th_pa) and outputs, the gait's nominal stance motor torque u*(tau) plus
    the JOINT-side feedback knee -kp y2 - kd dy2 and ankle k_vhip y1 (N m per m/s of hip
    velocity error: positive ankle torque, plantarflexion, brakes the shank's forward
    rotation over the flat foot, so a hip too fast is slowed).  ``feedforward = False``
    drops u*."""

    kp: Positive = 1500.0
    kd: NonNegative = 30.0
    k_vhip: float = 250.0
    feedforward: bool = True


class PassiveConfig(StrictConfig):
    """Spong's robust passivity-based law (REFERENCE.md Sec. 2), JOINT-side gains.

    ``lam``: Lambda (1/s) in e_dot + Lambda e; ``k``: K (N m s/rad); ``rho_theta``: bound
    on the parameter error |theta - theta0| (SI units of the inertial parameters
    (m, m c_x, m c_z, I_joint) per moving link); ``boundary``: boundary-layer width of
    |Y^T r| below which the robust term is linear (avoids chattering)."""

    # Lambda, K: chosen by orchestrator.experiments.baseline_gains (PdConfig)
    lam: Pair = (60.0, 60.0)
    k: Pair = (400.0, 400.0)
    rho_theta: NonNegative = 0.2
    boundary: Positive = 0.5


class SwingConfig(StrictConfig):
    """Shared swing (pns) controller: PD + gravity feedforward on the pns Bezier rows of
    th_pk and th_pa at the time-based phase tau_hat = (t - t_liftoff) / T_pns. JOINT gains.

    Landing (``terms.swing_ref``): from tau_hat = ``landing_start`` the knee turns the shank
    toward the vertical under the knee (lowering the sole at a fixed foot pitch) by the
    fraction landing_reach (tau_hat - landing_start) / (1 - landing_start) of its angle,
    capped at 1 (it keeps reaching when the touchdown is late), and the ankle turns the foot
    flat (world pitch 0 at the nominal socket pitch) over the next ``landing_flatten`` of
    tau_hat.  ``landing_reach = 0`` only flattens the foot.

    Thigh lead (``thigh_lead``, needs the socket IMU's pitch in the measurement): the human's
    swing is not the nominal one, and a foot that lands while the knee is still flexed
    slips.  Where the gait's nominal pns socket pitch falls monotonically (the thigh swinging
    forward) the measured pitch gives a phase s_thigh; while both s_thigh and tau_hat lie in
    ``lead_window`` the lead s_thigh - tau_hat is low-pass filtered (time constant
    ``lead_time_constant``, s) and, when positive, added to tau_hat (held for the rest of
    the swing, reset at lift-off).  It only advances the swing: a human slower than the
    nominal finds the prosthesis ready early and waiting.  ``lead_deadband`` (phase units) is
    taken off the lead first (an IMU bias of b rad moves the lead by b over the slope of
    the nominal pitch, about 1.3 rad per unit phase on the synthetic subject).  Without
    a pitch (NaN) or a monotonic branch the swing runs on the clock alone."""

    kp: Pair = (2000.0, 135.0)
    kd: Pair = (24.0, 1.6)
    gravity: bool = True
    landing_reach: UnitInterval = 0.1
    landing_start: float = Field(0.8, gt=0, lt=1)
    landing_flatten: Positive = 0.05
    thigh_lead: bool = True
    lead_window: tuple[float, float] = (0.2, 0.65)
    lead_time_constant: Positive = 0.03
    lead_deadband: float = Field(0.0, ge=0, lt=1)
    lead_min_slope: float = Field(0.75, ge=0, lt=1)

    @model_validator(mode="after")
    def _window(self) -> SwingConfig:
        lo, hi = self.lead_window
        if not 0.0 <= lo < hi <= 1.0:
            raise ValueError("lead_window must be 0 <= low < high <= 1")
        return self


class DomainConfig(StrictConfig):
    """Domain detection with hysteresis from the foot-load cell and the contact switch.

    Stance (ps) starts when ``contact`` and load >= ``load_on``; swing (pns) starts when
    not ``contact``, or when load <= ``load_off`` has held for ``off_hold`` s with contact (a
    one-tick dip of the load, e.g. the rigid contact's response to a torque step, is not a
    lift-off); no switch within ``min_dwell`` of the last.  ``initial``: the domain assumed
    after ``reset()``."""

    load_on: Positive = 150.0
    load_off: NonNegative = 40.0
    off_hold: NonNegative = 0.01
    min_dwell: NonNegative = 0.08
    initial: Domain = Domain.PS

    @model_validator(mode="after")
    def _hysteresis(self) -> DomainConfig:
        if not self.load_on > self.load_off:
            raise ValueError("load_on must exceed load_off (hysteresis)")
        return self


class SafetyConfig(StrictConfig):
    """Measurement validation and output limits.

    ``torque_limits``: motor N m (knee, ankle); ``None`` takes the device's
    (``model.torque_limits[4:]``).  ``fallback_rate``: the per-tick step of every fallback
    (motor N m).  A measurement with a non-finite field, an angle outside ``knee_range`` /
    ``ankle_range``, a speed above ``max_speed``, a load outside ``load_range`` (a small
    negative reading is load-cell offset) or a time that does not increase is a fault."""

    torque_limits: Pair | None = None
    fallback_rate: Positive = 0.25
    knee_range: Pair = (-0.35, 2.2)
    ankle_range: Pair = (-0.9, 0.9)
    max_speed: Positive = 40.0
    load_range: Pair = (-100.0, 5000.0)


class ControllerConfig(StrictConfig):
    """All settings of every controller; each controller reads the parts it uses."""

    clf: ClfConfig = ClfConfig()
    contact: ContactConfig = ContactConfig()
    uncertainty: UncertaintyConfig = UncertaintyConfig()
    pd: PdConfig = PdConfig()
    phase_pd: PhasePdConfig = PhasePdConfig()
    passive: PassiveConfig = PassiveConfig()
    swing: SwingConfig = SwingConfig()
    domain: DomainConfig = DomainConfig()
    safety: SafetyConfig = SafetyConfig()
