"""The robust CLF-QP on the multi-contact graph (:class:`ContactClfQp`): the interaction-aware
CLF-QP of ``clfqp`` (:mod:`prosthesis_controller.loop_clfqp`) in every domain where the
prosthesis foot is on the ground, from AMPRO3's own sensors.

- **Phase**: contact-pd's (:class:`~prosthesis_controller.contact_phase_pd.ContactPhasePD`):
  in stance the hip's progress over the heel's ground point from the socket IMU and the
  encoders (one phase across ``ds_p``, ``ps``, ``ps_toe`` and ``ds_h``), in swing the time
  since toe-off.  The swing runs contact-pd's law (joint PD and the gait's torque).
- **Model** (stance): the human-prosthesis loop restricted to the nominal human
  (:mod:`hp_model.contact_interaction`), in the domain the gait is in at the phase (but
  ``ds_p``'s last sample while the gait's foot is flat and the sensed one is still on its
  heel, :data:`HEEL_DOWN`; and ``ds_h`` from the person's heel strike sensed at the joints
  while the gait is in ``ps_toe``, read at the time since it: :class:`HeelStrikeSensor`,
  :meth:`ContactClfQp._after_strike`) and at the gait's walker state there (one stance as the
  model walks it, :class:`WalkedStance`), linearized about the gait:

      qdd_p = qdd_ref + g (u - u_ref),     w = w_ref + W (u - u_ref)

  with qdd_ref, w_ref, u_ref the gait's prosthesis joint accelerations (rad/s^2), contact
  wrenches (every contact on the ground, N and N m) and motor torques (N m) at the phase,
  g and W the interaction model's torque authority.  Not the affine model's own drift at
  the measured state (f + g u, as ``clfqp`` on the paper's domains): with the human's state
  from the gait at the phase and the prosthesis joints from the encoders, the nominal human's
  feedback linearization saw output-velocity errors the real one did not and answered
  them, and the drift was off by 10-100 rad/s^2 within 50 ms of a stance; the controller
  fell 68 ms into the committed cycle's first stance.  The authority g was within 0.3 % of
  the true state's.  Everything of the QP below that depends on the phase alone (g, W, the
  cost, the contact rows) is evaluated once along that stance (:class:`StanceQp`, 1 ms
  samples); a tick adds the CLF row and the torque box.
- **Outputs**: the knee's and the ankle's deviations from the gait at the phase,
  eta = (e_k, e_a, de_k, de_a); nu = qdd_p - qdd_ref = g (u - u_ref).  A RES-CLF of the
  two double integrators, the sum of each joint's (:class:`JointClf`: CARE with Q = I,
  R = 1, the position scaled by 1/eps, the paper's eps).
- **Robust term** (the paper's, on this model): where the gait's force tube carries the
  bound of this model's error d = qdd_true - qdd_ref - g (u - u_ref) (rad/s^2, per joint;
  :mod:`characterization.tube.contact_model_error`: characterised by playback of the
  recorded flat single supports, the tube's phase range of ``ps``), its worst case over the
  box [c_d - r_d, c_d + r_d] enters the CLF row: dV/dnu . c_d + |dV/dnu| . r_d.  Zero
  elsewhere, and without a bound.
- **QP**, z = (u_k, u_a, rho, sigma):

      min  |nu|^2 + w_force |(w - w_ref) / W_body|^2 + w_torque |u - u_ref|^2
           + c_rho rho + c_sigma sigma                  (over its trace, for piqp)
      s.t. LgV u - rho <= -(gamma/eps) V - LfV - dV/dnu c_d - |dV/dnu| r_d   (the CLF)
           per contact: |F_x| <= mu F_z + sigma, F_z >= f_min - sigma; a flat sole's centre
           of pressure on the sole (rows in body weights)
           max(-u_max, u_prev - du) <= u <= min(u_max, u_prev + du), 0 <= rho, 0 <= sigma

  The force term sets the load split where the motion does not: in ``ds_p`` the human
  holds the prosthesis sole's pitch, and the prosthesis's two torques move one joint
  acceleration (g has rank 1); the other direction presses the feet against each other
  along the ground (the gait's squeeze).  The torque term keeps the solution unique.
  f_min of a contact is half the gait's normal force where that is lower (a trailing toe
  unloads to zero as its double support ends).
- **Measured load**: the contact rows' wrench is the gait's shifted by what the foot's load
  cell reads above the model's prediction under the last tick's torque (that much more
  normal force on the prosthesis foot, and as much less on the person's other foot in a
  double support): the rows hold the contacts as they are, not as the gait has them.

Every torque is bounded at the motors; a measurement it cannot use (a non-finite field or no
IMU pitch) gives zero torque; a QP that piqp cannot solve (retried once at 100x its
tolerance) gives contact-pd's torque.
"""

from __future__ import annotations

import bisect
import math
from collections.abc import Mapping
from dataclasses import dataclass, field, replace

import numpy as np
import piqp
from scipy.linalg import solve_continuous_are

from hp_model.compiled import FunctionSet
from hp_model.contact_interaction import STANCE_DOMAINS, wrench_size
from hp_model.domains import Domain
from hp_model.force_tube import CONTACT_ERROR_COMPONENTS, ModelErrorBound
from hp_model.human_prosthesis import HumanProsthesisModel
from prosthesis_controller.contact_phase_pd import (
    ContactGaitTables,
    ContactPhasePD,
    control_output,
)
from prosthesis_controller.heel_strike import HeelStrikeSensor
from prosthesis_controller.interface import ControllerMode, ControlOutput, QpOutcome
from prosthesis_controller.measurement import ProsthesisMeasurement
from prosthesis_controller.qp import dense_solver, set_tolerance

#: the largest number of contact wrench rows of a stance domain (a double support: 2 + 2)
MAX_WRENCH = 4
#: rad: a sensed heel this far below the toe is still on its heel, not flat (the plant lands
#: the foot flat at 0; the sensors' noise, 0.2 deg per encoder in the sweeps' sensor family,
#: does not hold it again once it read flat: :attr:`ContactClfQp.landed`)
HEEL_DOWN = math.radians(0.5)
#: a foot sensed flat carrying less than this share of the flat foot's load the model
#: predicts is still in the double support (the person's trailing toe loaded)
FLAT_LOAD = 0.9
#: the largest number of contact rows of a stance domain's QP (a double support: 3 per
#: heel or toe; a flat sole: 5)
MAX_CONTACT_ROWS = 6
#: s: a foot sensed flat and loaded at least this long before the gait's landing (at the
#: gait's pace) landed early: the flat stance's QP from then on
#: (:meth:`ContactClfQp._landed_early`); nearer the gait's landing the double support's QP
#: holds, as on the gait: a foot read flat there may still be on its heel, and the flat
#: stance's QP pulled it off the ground (switched 10-13 ms before it at speed changes, 33 ms
#: on the packaged person's library at 1.2 m/s; the early landings it is for read flat
#: 76-92 ms before it, docs/gait-design.md)
EARLY_FLAT = 0.06
#: rad: a foot that flat (the leg's sensed heel within this of its toe) has landed before the
#: gait's (:meth:`ContactClfQp._landed_early`): a foot that landed reads flat to the sensors'
#: precision; on openOFM's cycle the foot rolls down to within 0.47 deg of flat 43 ms before
#: the gait's landing, still on its heel, and the flat stance's QP pulled it off the ground
EARLY_FLAT_PITCH = math.radians(0.1)
#: ticks in a row a foot must read that flat: the sweeps' encoder noise (0.2 deg) put a foot
#: 0.47 deg from flat within 0.1 deg for single ticks on openOFM's cycle
EARLY_FLAT_TICKS = 5
#: s: the time between two samples of the stance QP (:class:`WalkedStance`: one per period of
#: the plant the held walk ran on); the person's heel strike sensed, ``ds_h``'s samples are
#: read at the time since it
SAMPLE_PERIOD = 1e-3


@dataclass(frozen=True)
class ContactClfConfig:
    """The CLF-QP's constants (module docstring): ``eps`` (the RES-CLF's, s), ``gamma``,
    ``w_force`` (per body weight squared, in units of (rad/s^2)^2), ``w_torque``
    ((rad/s^2)^2 per (N m)^2 motor), ``c_rho``, ``c_sigma`` (per body weight), ``mu``,
    ``f_min`` (N), ``delta_u`` (N m motor per tick), ``solver_eps`` (piqp's tolerances),
    ``strike_window`` (periods) and ``strike_threshold`` (rad/s^2; inf: never) of the
    person's heel strike sensed at the joints (:class:`HeelStrikeSensor`)."""

    eps: float = 0.02
    gamma: float = 0.3
    w_force: float = 1.0e4
    w_torque: float = 1.0
    c_rho: float = 1.0e1
    c_sigma: float = 1.0e6
    mu: float = 0.6
    f_min: float = 30.0
    delta_u: float = 5.0
    solver_eps: float = 1e-8
    strike_window: int = 3
    strike_threshold: float = 100.0


#: the defaults (measured in docs/gait-design.md)
DEFAULT_CONFIG = ContactClfConfig()


@dataclass(frozen=True)
class Sole:
    """A flat sole's heel and toe distances from its sole frame (m, along the sole)."""

    heel: float
    toe: float


def soles(model: HumanProsthesisModel) -> dict[str, Sole]:
    """Each foot's :class:`Sole` ("p", "l") from the model's frames at the zero posture."""
    pose = np.asarray(model.numeric()["frames"](np.zeros(model.nq), np.zeros(model.nq))[0])
    x = {n: float(pose[0, model.frame_index(n)]) for n in model.frame_names}
    return {s: Sole(x[f"{s}_sole"] - x[f"{s}_heel"], x[f"{s}_toe"] - x[f"{s}_sole"])
            for s in ("p", "l")}


def contact_rows(domain: Domain, W: np.ndarray, w0: np.ndarray, w_ref: np.ndarray, mu: float,
                 f_min: float, soles: Mapping[str, Sole]) -> list[tuple[np.ndarray, float]]:
    """The contact rows (a u <= b, before the slack) of ``domain``'s contacts for the wrench
    w = w0 + W u (per contact (F_x, F_z[, M_y]) in contact order; body weights and body
    weights x m): each contact in its friction cone ``mu`` with a normal force of at least
    ``f_min`` or half the gait's (``w_ref``) where that is lower; a flat sole's centre of
    pressure -M_y / F_z between its heel and toe."""
    rows, k = [], 0
    for contact in domain.contacts:
        x, z = k, k + 1
        least = min(f_min, 0.5 * max(float(w_ref[z]), 0.0))
        rows += [(W[x] - mu * W[z], mu * w0[z] - w0[x]),
                 (-W[x] - mu * W[z], mu * w0[z] + w0[x]),
                 (-W[z], w0[z] - least)]
        if contact.is_flat:
            sole, m = soles[contact.side], k + 2
            rows += [(-(sole.toe * W[z] + W[m]), sole.toe * w0[z] + w0[m]),
                     (-(sole.heel * W[z] - W[m]), sole.heel * w0[z] - w0[m])]
        k += contact.size
    return rows


def load_shift(domain: Domain) -> np.ndarray:
    """The wrench (per contact (F_x, F_z[, M_y]), contact order) of one unit more normal
    force on the prosthesis foot than the model's, and as much less on the other foot in a
    double support (the body's weight is shared between them): what a load cell's reading
    above the model's tells of the wrench."""
    e, k = np.zeros(wrench_size(domain)), 0
    for contact in domain.contacts:
        e[k + 1] = 1.0 if contact.side == "p" else -1.0
        k += contact.size
    return e


def prosthesis_normal(domain: Domain) -> int:
    """The wrench row of the prosthesis foot's normal force in ``domain`` (a stance one)."""
    return int(np.flatnonzero(load_shift(domain) > 0)[0])


def qp_rows(domain: Domain) -> int:
    """Rows of ``domain``'s QP: the CLF's and its contacts'."""
    return 1 + sum(5 if c.is_flat else 3 for c in domain.contacts)


@dataclass(frozen=True)
class StanceQp:
    """Everything of the QP that depends on the phase alone (module docstring), per sample of
    one stance as the model walks it (``phase`` (n,), non-decreasing): ``domain`` (n,) the
    gait's domain; ``g`` (n, 2, 2) the torque authority on the joint accelerations
    (rad/s^2 per motor N m); ``u_ref`` (n, 2) the gait's motor torques (N m); ``qdd_ref``
    (n, 2) its prosthesis joint accelerations (rad/s^2); ``P`` (n, 4, 4) and ``c`` (n, 4) the
    cost in z = (u, rho, sigma); ``G`` (n, 6, 4) and ``h`` (n, 6) the contact rows (a
    domain's first ``qp_rows(d) - 1``; their slack sigma in body weights); ``d_center``,
    ``d_radius`` (n, 2) the model error's box (rad/s^2; zero where no bound holds: the
    robust term); ``load_ref`` (n,) the prosthesis foot's normal force in the gait (N),
    ``load_gain`` (n, 2) its change per motor N m and ``load_h`` (n, 6) the change of the
    contact rows' h per N of load the load cell measures above the model's (the rest of
    the body's weight on the other foot in a double support: :meth:`ContactClfQp._stance`)."""

    phase: np.ndarray
    domain: tuple[Domain, ...]
    g: np.ndarray
    u_ref: np.ndarray
    qdd_ref: np.ndarray
    P: np.ndarray
    c: np.ndarray
    G: np.ndarray
    h: np.ndarray
    d_center: np.ndarray
    d_radius: np.ndarray
    load_ref: np.ndarray
    load_gain: np.ndarray
    load_h: np.ndarray

    _phases: list[float] = field(init=False, repr=False, compare=False)
    g_rows: list[list[list[float]]] = field(init=False, repr=False, compare=False)
    u_rows: list[list[float]] = field(init=False, repr=False, compare=False)
    qdd_rows: list[list[float]] = field(init=False, repr=False, compare=False)
    margin_rows: list[list[float]] = field(init=False, repr=False, compare=False)
    load_rows: list[list[float]] = field(init=False, repr=False, compare=False)
    #: (n, 2, 6): h and load_h of each sample, for the tick's one product
    rows_h: np.ndarray = field(init=False, repr=False, compare=False)
    #: the last ``ds_p`` sample (-1: none): where a foot still on its heel is held
    heel_end: int = field(init=False, repr=False, compare=False)
    #: the first and the last ``ds_h`` sample ((-1, -1): none): the person's heel strike on
    strike_span: tuple[int, int] = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        # the phases, g and u_ref as floats: a search ~0.3 us, not numpy's ~1.5 us, and the
        # CLF row in float arithmetic (the tick is held to 40 us,
        # benchmarks/bench_contact_controllers.py)
        object.__setattr__(self, "_phases", self.phase.tolist())
        object.__setattr__(self, "g_rows", self.g.tolist())
        object.__setattr__(self, "u_rows", self.u_ref.tolist())
        object.__setattr__(self, "qdd_rows", self.qdd_ref.tolist())
        object.__setattr__(self, "margin_rows", np.hstack(
            [np.reshape(self.d_center, (-1, 2)), np.reshape(self.d_radius, (-1, 2))]).tolist())
        object.__setattr__(self, "rows_h", np.stack([self.h, self.load_h], axis=1))
        object.__setattr__(self, "load_rows", np.column_stack(
            [self.load_ref, np.reshape(self.load_gain, (-1, 2))]).tolist())
        heel = [i for i, d in enumerate(self.domain) if d is Domain.DS_P]
        object.__setattr__(self, "heel_end", heel[-1] if heel else -1)
        struck = [i for i, d in enumerate(self.domain) if d is Domain.DS_H]
        object.__setattr__(self, "strike_span", (struck[0], struck[-1]) if struck else (-1, -1))

    def with_margin(self, bound: ModelErrorBound | None) -> StanceQp:
        """These samples with the robust term of ``bound`` (the multi-contact model error,
        :data:`hp_model.force_tube.CONTACT_ERROR_COMPONENTS`): its box at each ``ps`` sample
        inside its phase range, zero elsewhere; ``None``: no robust term."""
        center, radius = np.zeros((len(self.phase), 2)), np.zeros((len(self.phase), 2))
        if bound is not None:
            if bound.components != CONTACT_ERROR_COMPONENTS:
                raise ValueError(f"the model-error bound is of {list(bound.components)}, not "
                                 f"the multi-contact controller's "
                                 f"{list(CONTACT_ERROR_COMPONENTS)}")
            on = (np.array([d is Domain.PS for d in self.domain])
                  & (self.phase >= bound.tau_lo) & (self.phase <= bound.tau_hi))
            if on.any():
                lo, hi = bound.bounds(self.phase[on])
                center[on], radius[on] = 0.5 * (lo + hi), 0.5 * np.maximum(hi - lo, 0.0)
        return replace(self, d_center=center, d_radius=radius)

    def index(self, s: float) -> int:
        """The sample at or before phase ``s`` (the first or the last outside the stance)."""
        return min(max(bisect.bisect_right(self._phases, s) - 1, 0), len(self._phases) - 1)


def domain_spans(st: StanceQp) -> list[tuple[Domain, int, int]] | None:
    """The stance's domains in their order, each with its first and last sample (None if a
    domain comes back after another)."""
    spans: list[tuple[Domain, int, int]] = []
    for i, d in enumerate(st.domain):
        if spans and spans[-1][0] is d:
            spans[-1] = (d, spans[-1][1], i)
        elif any(x is d for x, _, _ in spans):
            return None
        else:
            spans.append((d, i, i))
    return spans


def blend_stance(a: StanceQp, b: StanceQp, w: float) -> StanceQp:
    """The stance QP's data (1 - w) a + w b (0 <= w <= 1; two speeds' of a gait library),
    domain by domain: each domain's span of the phase blended between the two's (the
    domains' boundaries move with the speed), each of the nearer's samples (a for w <= 0.5)
    placed at its share of its domain's span and blended with the other's sample at or
    before the same share of its.  Two stances whose domains differ: on the nearer's grid,
    the other's sample at or before each phase blended in where the two are in the same
    domain, the nearer's alone where not."""
    if w > 0.5:
        a, b, w = b, a, 1.0 - w
    sa, sb = domain_spans(a), domain_spans(b)
    phase = a.phase.copy()
    if sa is not None and sb is not None and [d for d, _, _ in sa] == [d for d, _, _ in sb]:
        j = np.zeros(len(a.phase), dtype=int)
        for (_, i0, i1), (_, k0, k1) in zip(sa, sb, strict=True):
            pa, pb = a.phase[i0:i1 + 1], b.phase[k0:k1 + 1]
            share = (pa - pa[0]) / (pa[-1] - pa[0]) if pa[-1] > pa[0] else np.zeros(pa.size)
            at = pb[0] + share * (pb[-1] - pb[0])
            phase[i0:i1 + 1] = (1.0 - w) * pa + w * at
            j[i0:i1 + 1] = k0 + np.clip(np.searchsorted(pb, at, side="right") - 1, 0,
                                        k1 - k0)
        same = np.ones(len(a.phase), dtype=bool)
    else:
        j = np.array([b.index(s) for s in a.phase])
        same = np.array([da is b.domain[k] for da, k in zip(a.domain, j, strict=True)])

    def mix(x: np.ndarray, y: np.ndarray) -> np.ndarray:
        out = np.array(x, dtype=float, copy=True)
        out[same] = (1.0 - w) * x[same] + w * y[j][same]
        return out

    return StanceQp(phase, a.domain, *(mix(getattr(a, k), getattr(b, k)) for k in
                                       ("g", "u_ref", "qdd_ref", "P", "c", "G", "h",
                                        "d_center", "d_radius", "load_ref", "load_gain",
                                        "load_h")))


@dataclass(frozen=True)
class WalkedStance:
    """One stance as the model walks it, sampled each period: ``phase`` (n,) its stance
    phase; ``domain`` (n,) domain codes; ``q``, ``qd`` (n, nq) the walker's state;
    ``wrench`` (n, 4) its contact wrenches (zero-padded; N, N m); ``torque`` (n, 2) the
    prosthesis's motor torques (N m)."""

    phase: np.ndarray
    domain: np.ndarray
    q: np.ndarray
    qd: np.ndarray
    wrench: np.ndarray
    torque: np.ndarray


def stance_qp(walked: WalkedStance, interaction: FunctionSet,
              thetas: Mapping[Domain, np.ndarray], gains: tuple[float, float, float],
              model: HumanProsthesisModel, config: ContactClfConfig = DEFAULT_CONFIG
              ) -> StanceQp:
    """The :class:`StanceQp` along ``walked``: ``interaction`` the compiled
    :class:`~hp_model.contact_interaction.ContactInteraction`; ``thetas``, ``gains`` the
    gait's and the human's.  In du = u - u_ref: nu = g du, w = w_ref + W du."""
    phase, q, qd, wrench, u_ref = (walked.phase, walked.q, walked.qd, walked.wrench,
                                   np.asarray(walked.torque, float))
    domain = walked.domain
    weight = float(model.tree.total_mass) * 9.81
    feet = soles(model)
    n = len(phase)
    doms = tuple(Domain.from_code(int(c)) for c in domain)
    g_all, P_all, acc_all = np.zeros((n, 2, 2)), np.zeros((n, 4, 4)), np.zeros((n, 2))
    c_all, G_all = np.zeros((n, 4)), np.zeros((n, MAX_CONTACT_ROWS, 4))
    h_all = np.ones((n, MAX_CONTACT_ROWS))
    load_ref, load_gain = np.zeros(n), np.zeros((n, 2))
    load_h = np.zeros((n, MAX_CONTACT_ROWS))
    for i, d in enumerate(doms):
        f, g, _, W = (np.asarray(a) for a in interaction[f"interaction_{d}"](
            q[i], qd[i], np.asarray(thetas[d], float), np.asarray(gains, float)))
        acc_all[i] = f.ravel() + g @ u_ref[i]
        nw = wrench_size(d)
        Wn, wn = W / weight, wrench[i, :nw] / weight  # body weights
        H = g.T @ g + config.w_force * Wn.T @ Wn + config.w_torque * np.eye(2)
        g_all[i] = g
        # the cost over trace(H) (the same minimizer): piqp in 9 iterations, not 12
        k = float(np.trace(H))
        P_all[i, :2, :2] = 2.0 * H / k
        P_all[i, 2, 2] = P_all[i, 3, 3] = 1e-9
        c_all[i] = (*(-2.0 * H @ u_ref[i] / k), config.c_rho / k, config.c_sigma / k)
        w0 = wn - Wn @ u_ref[i]
        rows = contact_rows(d, Wn, w0, wn, config.mu, config.f_min / weight, feet)
        shifted = contact_rows(d, Wn, w0 + load_shift(d), wn, config.mu,
                               config.f_min / weight, feet)  # rows affine in w0
        for r, ((row_u, row_h), (_, row_s)) in enumerate(zip(rows, shifted, strict=True)):
            G_all[i, r, :2], G_all[i, r, 3], h_all[i, r] = row_u, -1.0, row_h
            load_h[i, r] = (row_s - row_h) / weight
        z = prosthesis_normal(d)
        load_ref[i], load_gain[i] = wrench[i, z], W[z]
    return StanceQp(np.asarray(phase, float), doms, g_all, np.asarray(u_ref, float), acc_all,
                    P_all, c_all, G_all, h_all, np.zeros((n, 2)), np.zeros((n, 2)), load_ref,
                    load_gain, load_h)


@dataclass(frozen=True)
class JointClf:
    """The RES-CLF of one joint's deviation, a double integrator (e, de) with de_dot = nu:
    V = p11 e^2 + 2 p12 e de + p22 de^2 (CARE with Q = I, R = 1, the position scaled by
    1/eps).  The two joints' CLF is the sum of theirs (the CARE of the pair decouples)."""

    p11: float
    p12: float
    p22: float

    def terms(self, e: float, de: float) -> tuple[float, float, float]:
        """(V, dV/dt at nu = 0, dV/dnu) of the deviation e (rad) and its rate de (rad/s)."""
        p11, p12, p22 = self.p11, self.p12, self.p22
        return (p11 * e * e + 2.0 * p12 * e * de + p22 * de * de,
                2.0 * (p11 * e + p12 * de) * de, 2.0 * (p12 * e + p22 * de))

    @classmethod
    def of(cls, eps: float) -> JointClf:
        if not 0 < eps < 1:
            raise ValueError(f"eps must lie in (0, 1), got {eps}")
        F, G = np.array([[0.0, 1.0], [0.0, 0.0]]), np.array([[0.0], [1.0]])
        P = solve_continuous_are(F, G, np.eye(2), np.eye(1))
        return cls(float(P[0, 0]) / eps**2, float(P[0, 1]) / eps, float(P[1, 1]))


class ContactClfQp:
    """The controller of the module docstring, one tick per measurement: motor torques
    (knee, ankle; N m) clamped to the motors' limits, with the product's diagnostics (the
    stance domain the gait has at the phase, pns in swing; the CLF's value and relaxation in
    stance; mode fallback where piqp cannot solve, fault for a measurement it cannot use)."""

    name = "clfqp"
    relaxed = True  # its CLF row has a relaxation (the node reports rho)

    def __init__(self, phase_law: ContactPhasePD, stance: StanceQp,
                 limits: tuple[float, float], config: ContactClfConfig = DEFAULT_CONFIG
                 ) -> None:
        self.law, self.stance, self.config = phase_law, stance, config
        self._clf = JointClf.of(config.eps)
        self._limits = (float(limits[0]), float(limits[1]))
        #: each domain's G, h buffers; its piqp solver is set up by :meth:`reset`
        self._G = {d: np.zeros((qp_rows(d), 4)) for d in STANCE_DOMAINS}
        self._h = {d: np.zeros(qp_rows(d)) for d in STANCE_DOMAINS}
        self._solvers: dict[Domain, piqp.DenseSolver] = {}
        self._z: dict[Domain, np.ndarray] = {}
        self._xl = np.array([0.0, 0.0, 0.0, 0.0])
        self._xu = np.array([0.0, 0.0, math.inf, 1.0])
        self._coef = np.array([1.0, 0.0])  # (1, the load cell's excess in N)
        self._strike = HeelStrikeSensor(config.strike_window, config.strike_threshold)
        self.keep_qp = False  # set to keep each stance tick's QP in ``qp``
        self.reset()

    def reset(self, torque: tuple[float, float] | None = None) -> None:
        """Forget all state; ``torque``: the previous torque to assume (N m, default 0; the
        torque-rate box starts from it)."""
        self.law.reset()
        self._new_solvers()
        lk, la = self._limits
        u = (0.0, 0.0) if torque is None else (float(torque[0]), float(torque[1]))
        self._u = (min(max(u[0], -lk), lk) if math.isfinite(u[0]) else 0.0,
                   min(max(u[1], -la), la) if math.isfinite(u[1]) else 0.0)
        self.fallbacks = 0  # ticks whose torque came from a fallback (no QP solution, fault)
        #: whether this stance's foot has been sensed flat (HEEL_DOWN; set at the first flat
        #: reading where the gait's foot is flat, cleared at the heel strike)
        self.landed = False
        #: the ticks in a row the foot has read flat before the gait's landing
        self._flat_ticks = 0
        self._strike.reset()
        #: the last tick's sample while the gait has the prosthesis on its toe at the phase
        #: and no heel strike of the person is sensed (None otherwise)
        self._i_prev: int | None = None
        #: the last stance tick's domain (as the gait has it at the phase; None in swing), the
        #: CLF's value, the relaxations and whether piqp solved it
        self.domain: Domain | None = None
        self.V = self.rho = self.sigma = 0.0
        self.solved = True
        #: the last stance QP as piqp got it (copies): (P, c, G, h, x_l, x_u),
        #: min 1/2 z^T P z + c^T z, G z <= h, x_l <= z <= x_u
        self.qp: tuple[np.ndarray, ...] | None = None

    def blended(self, other: ContactClfQp, w: float) -> ContactClfQp:
        """This controller with its references and stance QP blended with ``other``'s,
        (1 - w) these + w other's (:meth:`ContactPhasePD.blended`, :func:`blend_stance`)."""
        return ContactClfQp(self.law.blended(other.law, w),
                            blend_stance(self.stance, other.stance, w), self._limits,
                            self.config)

    def take_over(self, other: ContactClfQp) -> None:
        """Continue from ``other``'s state (another gait's controller of the same leg and
        motors: a switch of speed, :mod:`prosthesis_controller.speed_following`): its phase
        law's, the torque its rate limit starts from and its counts."""
        self.law.take_over(other.law)
        self._u, self.fallbacks, self.landed = other._u, other.fallbacks, other.landed
        self._flat_ticks = other._flat_ticks
        self._strike.reset()  # its samples are the other stance's: the window starts again
        self._strike.struck_at = other._strike.struck_at
        self._i_prev = None

    def _new_solvers(self) -> None:
        """One piqp solver per domain, set up with its rows (a solver keeps its scaling and
        iterates from solve to solve: a run after a reset does not depend on the runs
        before it, tests/test_sweep_contact.py)."""
        for d in STANCE_DOMAINS:
            rows = qp_rows(d)
            self._solvers[d] = dense_solver(
                self.config.solver_eps, P=np.eye(4), c=np.zeros(4), G=np.ones((rows, 4)),
                h_l=np.full(rows, -math.inf), h_u=np.ones(rows), x_l=-np.ones(4),
                x_u=np.ones(4))
            # one equilibration pass, not piqp's 10: its update + solve 19 us, not 24, on
            # the committed cycle's stance QPs; the torques within 1e-4 N m of the default's
            # (the QP is strictly convex in them) (the tick is held to 40 us)
            self._solvers[d].settings.preconditioner_iter = 1
            #: its solution, read through a view made once (piqp keeps its result in
            #: place; ``result`` makes a new object, ~1 us)
            self._z[d] = self._solvers[d].result.x

    @property
    def phase(self) -> float:
        return self.law.phase

    @property
    def tables(self) -> ContactGaitTables:
        """Its phase law's gait tables."""
        return self.law.tables

    def tick(self, m: ProsthesisMeasurement) -> ControlOutput:
        fields = (m.t, m.knee_angle, m.ankle_angle, m.knee_vel, m.ankle_vel, m.socket_pitch)
        if not all(math.isfinite(v) for v in fields):
            self._u = (0.0, 0.0)
            self.fallbacks += 1
            return control_output(self._u, self.law.phase, Domain.PNS, ControllerMode.FAULT,
                                  self.fallbacks)
        law = self.law
        if m.contact and not law.in_stance:  # a heel strike
            self.landed = False
            self._flat_ticks = 0
            self._strike.reset()
        ref = law.reference(m)  # the phase and the gait there
        u = None
        self.domain = None
        mode, qp = ControllerMode.SWING, QpOutcome.NOT_RUN
        if m.contact:
            u = self._stance(m, law.phase, ref)
            mode, qp = ControllerMode.STANCE, QpOutcome.SOLVED
            if u is None:
                mode, qp = ControllerMode.FALLBACK, QpOutcome.FAILED
                self.fallbacks += 1
        if u is None:  # swing, or no solution: contact-pd's law
            u = law.torque(m, ref)
        (lk, la) = self._limits
        self._u = (min(max(u[0], -lk), lk), min(max(u[1], -la), la))
        stance = self.domain is not None
        return control_output(self._u, law.phase, self.domain or Domain.PNS, mode,
                              self.fallbacks, V=self.V if stance else 0.0,
                              rho=self.rho if stance else 0.0, qp=qp)

    def _on_heel(self, m: ProsthesisMeasurement, i: int) -> bool:
        """Whether the foot is not yet flat at sample ``i`` of the gait's flat foot: its
        heel sensed below its toe by more than :data:`HEEL_DOWN`, or its load cell reading
        less than :data:`FLAT_LOAD` of the flat foot's load the model predicts under the
        last torque (the person's other foot still on the ground: the plant leaves ``ds_p``
        when that foot lets go)."""
        if self.law.rise < -HEEL_DOWN:
            return True
        excess = self._load_excess(m, i)
        if excess is None:
            return False  # no reading: the sensed angle alone
        return m.foot_load < FLAT_LOAD * (m.foot_load - excess)

    def _landed_early(self, m: ProsthesisMeasurement, i: int) -> bool:
        """Whether the foot has landed flat before the gait's at sample ``i`` of ``ds_p``:
        this stance's foot already sensed flat, or now: :data:`EARLY_FLAT_TICKS` ticks in a row
        within :data:`EARLY_FLAT_PITCH` of flat and not :meth:`_on_heel` at the flat stance's
        first sample (the flat foot's load), the gait's landing at least :data:`EARLY_FLAT`
        ahead."""
        st = self.stance
        first = st.heel_end + 1
        if not (0 < first < len(st.domain) and st.domain[first] is Domain.PS):
            return False
        if not self.landed and (first - i) * SAMPLE_PERIOD > EARLY_FLAT:
            flat = abs(self.law.rise) < EARLY_FLAT_PITCH and not self._on_heel(m, first)
            self._flat_ticks = self._flat_ticks + 1 if flat else 0
            self.landed = self._flat_ticks >= EARLY_FLAT_TICKS
        return self.landed

    def _after_strike(self, m: ProsthesisMeasurement, i: int, d: Domain,
                      ref: tuple[float, ...]) -> tuple[int, Domain, tuple[float, ...]]:
        """The sample, its domain and the gait there for this tick (sample ``i`` of domain
        ``d`` at the phase, the gait there ``ref``), the person's heel strike sensed at the
        joints while the gait is in ``ps_toe`` (:class:`HeelStrikeSensor`, fed the model's
        accelerations of the last tick's sample under the torque applied since): from the
        strike on, ``ds_h``'s sample at the time since it, or the phase's where that is
        later.  A person who struck early met ``ps_toe``'s push-off until the phase reached
        ``ds_h``, and then ``ds_h``'s entry: its heel was pulled off the ground
        (docs/gait-design.md, "The person's heel strike sensed at the prosthesis")."""
        st, sensor = self.stance, self._strike
        first, last = st.strike_span
        if sensor.struck_at is None:
            prev, self._i_prev = self._i_prev, (i if d is Domain.PS_TOE else None)
            if d is not Domain.PS_TOE or first < 0:
                sensor.restart()
                return i, d, ref
            if prev is None:  # the window starts here
                sensor.restart()
                sensor.update(m.t, m.knee_vel, m.ankle_vel, 0.0, 0.0)
                return i, d, ref
            (g00, g01), (g10, g11) = st.g_rows[prev]
            (a0, a1), (ur0, ur1), (u0, u1) = st.qdd_rows[prev], st.u_rows[prev], self._u
            du0, du1 = u0 - ur0, u1 - ur1
            if sensor.update(m.t, m.knee_vel, m.ankle_vel, a0 + g00 * du0 + g01 * du1,
                             a1 + g10 * du0 + g11 * du1) is None:
                return i, d, ref
        assert sensor.struck_at is not None
        since = first + round((m.t - sensor.struck_at) / SAMPLE_PERIOD)
        j = min(max(since, first), last)
        if d is Domain.DS_H and i >= j:
            return i, d, ref
        return j, Domain.DS_H, self.law.tables.stance.at(float(st.phase[j]))

    def _load_excess(self, m: ProsthesisMeasurement, i: int) -> float | None:
        """The load cell's reading above the model's prediction at sample ``i`` under the
        last tick's torque (N); None without a reading (zero, or not finite)."""
        load = m.foot_load
        if not (load > 0.0 and math.isfinite(load)):
            return None
        f_ref, w0, w1 = self.stance.load_rows[i]
        ur0, ur1 = self.stance.u_rows[i]
        u0, u1 = self._u
        return load - f_ref - w0 * (u0 - ur0) - w1 * (u1 - ur1)

    def _stance(self, m: ProsthesisMeasurement, s: float, ref: tuple[float, ...]
                ) -> tuple[float, float] | None:
        """The QP's torques at stance phase ``s``, the gait there ``ref`` (None if piqp
        cannot solve it)."""
        cfg, st = self.config, self.stance
        i = st.index(s)
        d = st.domain[i]
        if d is Domain.DS_P and self._landed_early(m, i):
            # the foot flat and carrying the flat foot's load while the gait's is still on its
            # heel (its foot slapped down, the hip behind): the flat stance's first QP and the
            # gait there (in ds_p's, whose torques move one joint direction, the CLF relaxed
            # and the person's weight extended the knee past straight, docs/gait-design.md)
            i, d = st.heel_end + 1, Domain.PS
            ref = self.law.tables.stance.at(float(st.phase[i]))
        elif d is Domain.PS and not self.landed and 0 <= st.heel_end < i:
            if self._on_heel(m, i):
                # the gait's foot is flat at this phase, the sensed one still on its heel or
                # the person's other foot still loaded (a person slower than the gait): the
                # QP and the reference of ds_p's end until it lands (at the gait's, the flat
                # foot's rows and the slap's velocity jump pulled the heel off the ground,
                # docs/gait-design.md)
                i, d = st.heel_end, Domain.DS_P
                ref = self.law.tables.stance.at(float(st.phase[i]))
            else:  # landed: the gait's from now on in this stance, whatever the noise reads
                self.landed = True
        if d is Domain.PS_TOE or d is Domain.DS_H:
            i, d, ref = self._after_strike(m, i, d, ref)
        k, a, vk, va, _, _ = ref
        # the CLF in floats, joint by joint (numpy's per-call cost on 4-vectors was ~5 us of
        # a tick held to 40 us, benchmarks/bench_contact_controllers.py)
        Vk, Lk, wk = self._clf.terms(m.knee_angle - k, m.knee_vel - vk)
        Va, La, wa = self._clf.terms(m.ankle_angle - a, m.ankle_vel - va)
        V, LfV = Vk + Va, Lk + La  # the CLF and its rate at du = 0
        (g00, g01), (g10, g11) = st.g_rows[i]
        lg0, lg1 = wk * g00 + wa * g10, wk * g01 + wa * g11  # LgV: its rate per du
        scale = max(math.hypot(lg0, lg1), 1e-9)
        ur0, ur1 = st.u_rows[i]
        c0, c1, r0, r1 = st.margin_rows[i]  # the model error's box (0 without a bound)
        margin = wk * c0 + wa * c1 + abs(wk) * r0 + abs(wa) * r1
        G, h = self._G[d], self._h[d]
        G[0, 0], G[0, 1], G[0, 2], G[0, 3] = lg0 / scale, lg1 / scale, -1.0 / scale, 0.0
        h[0] = (-cfg.gamma / cfg.eps * V - LfV - margin + lg0 * ur0 + lg1 * ur1) / scale
        n = G.shape[0] - 1
        G[1:] = st.G[i, :n]
        du, (lk, la), (u0, u1) = cfg.delta_u, self._limits, self._u
        # the load cell's reading above the model's there: the contact rows from the foot's
        # measured load, the other foot's from the rest (a heel strike off the gait pulled
        # the person's trailing toe off the ground under rows that read the gait's load
        # split, docs/gait-design.md)
        excess, coef = self._load_excess(m, i), self._coef
        coef[1] = 0.0 if excess is None else excess
        # h = h_gait + load_h * excess as one product into the QP's buffer: 0.9 us, not 1.6
        # (issue 38 holds the sweep's runs per minute and the tick to 40 us)
        np.dot(coef, st.rows_h[i, :, :n], out=h[1:])
        xl, xu = self._xl, self._xu
        xl[0], xu[0] = max(u0 - du, -lk), min(u0 + du, lk)
        xl[1], xu[1] = max(u1 - du, -la), min(u1 + du, la)
        sol = self._solvers[d]
        sol.update(P=st.P[i], c=st.c[i], G=G, h_u=h, x_l=xl, x_u=xu)
        status = sol.solve()
        if status != piqp.PIQP_SOLVED:
            set_tolerance(sol, 100.0 * cfg.solver_eps)
            status = sol.solve()
            set_tolerance(sol, cfg.solver_eps)
        if self.keep_qp:
            self.qp = tuple(np.array(v) for v in (st.P[i], st.c[i], G, h, xl, xu))
        self.domain, self.V = d, V
        self.solved = status == piqp.PIQP_SOLVED
        if not self.solved:
            return None
        z = self._z[d]
        self.rho, self.sigma = float(z[2]), float(z[3])
        return float(z[0]), float(z[1])
