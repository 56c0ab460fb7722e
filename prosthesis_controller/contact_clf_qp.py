"""The robust CLF-QP on the multi-contact graph (:class:`ContactClfQp`): the interaction-aware
CLF-QP of ``clfqp`` (:mod:`prosthesis_controller.loop_clfqp`) in every domain where the
prosthesis foot is on the ground, from AMPRO3's own sensors.

- **Phase**: contact-pd's (:class:`~prosthesis_controller.contact_phase_pd.ContactPhasePD`):
  in stance the hip's progress over the heel's ground point from the socket IMU and the
  encoders (one phase across ``ds_p``, ``ps``, ``ps_toe`` and ``ds_h``), in swing the time
  since toe-off.  The swing runs contact-pd's law (joint PD and the gait's torque).
- **Model** (stance): the human-prosthesis loop restricted to the nominal human
  (:mod:`hp_model.contact_interaction`), in the domain the gait is in at the phase and at
  the gait's walker state there (:class:`StanceModel`: one stance as the model walks it),
  linearized about the gait:

      qdd_p = qdd_ref + g (u - u_ref),     w = w_ref + W (u - u_ref)

  with qdd_ref, w_ref, u_ref the gait's prosthesis joint accelerations (rad/s^2), contact
  wrenches (every contact on the ground, N and N m) and motor torques (N m) at the phase,
  g and W the interaction model's torque authority.  Not the affine model's own drift at
  the measured state (f + g u, as ``clfqp`` on the paper's domains): with the human's state
  from the gait at the phase and the prosthesis joints from the encoders, the nominal human's
  feedback linearization saw output-velocity errors the real one did not and answered
  them, and the drift was off by 10-100 rad/s^2 within 50 ms of a stance; the controller
  fell 68 ms into the committed cycle's first stance.  The authority g was within 0.3 % of
  the true state's.
- **Outputs**: the knee's and the ankle's deviations from the gait at the phase,
  eta = (e_k, e_a, de_k, de_a); nu = qdd_p - qdd_ref = g (u - u_ref).  A RES-CLF
  V = eta^T P_eps eta of the two double integrators (CARE with Q = I, R = I; positions
  scaled by 1/eps, the paper's eps).
- **QP**, z = (u_k, u_a, rho, sigma):

      min  |nu|^2 + w_force |(w - w_ref) / W_body|^2 + w_torque |u - u_ref|^2
           + c_rho rho + c_sigma sigma
      s.t. LgV u - rho <= -(gamma/eps) V - LfV                            (the CLF)
           per contact: |F_x| <= mu F_z + sigma, F_z >= f_min - sigma; a flat sole's centre
           of pressure on the sole (rows in body weights)
           max(-u_max, u_prev - du) <= u <= min(u_max, u_prev + du), 0 <= rho, 0 <= sigma

  The force term sets the load split where the motion does not: in ``ds_p`` the human
  holds the prosthesis sole's pitch, and the prosthesis's two torques move one joint
  acceleration (g has rank 1); the other direction presses the feet against each other
  along the ground (the gait's squeeze).  The torque term keeps the solution unique.
  f_min of a contact is half the gait's normal force where that is lower (a trailing toe
  unloads to zero as its double support ends).

Every torque is bounded at the motors; a measurement it cannot use (a non-finite field or no
IMU pitch) gives zero torque; a QP that piqp cannot solve (retried once at 100x its
tolerance) gives contact-pd's torque.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np
import piqp
from scipy.linalg import solve_continuous_are

from hp_model.compiled import FunctionSet
from hp_model.contact_interaction import STANCE_DOMAINS, wrench_size
from hp_model.domains import PROSTHESIS, Domain
from hp_model.human_prosthesis import HumanProsthesisModel
from prosthesis_controller.contact_phase_pd import ContactPhasePD
from prosthesis_controller.measurement import ProsthesisMeasurement
from prosthesis_controller.qp import dense_solver, set_tolerance

#: the largest number of contact wrench rows of a stance domain (a double support: 2 + 2)
MAX_WRENCH = 4


@dataclass(frozen=True)
class ContactClfConfig:
    """The CLF-QP's constants (module docstring): ``eps`` (the RES-CLF's, s), ``gamma``,
    ``w_force`` (per body weight squared, in units of (rad/s^2)^2), ``w_torque``
    ((rad/s^2)^2 per (N m)^2 motor), ``c_rho``, ``c_sigma`` (per body weight), ``mu``,
    ``f_min`` (N), ``delta_u`` (N m motor per tick), ``solver_eps`` (piqp's tolerances)."""

    eps: float = 0.02
    gamma: float = 0.3
    w_force: float = 1.0e4
    w_torque: float = 1.0
    c_rho: float = 1.0e2
    c_sigma: float = 1.0e6
    mu: float = 0.6
    f_min: float = 30.0
    delta_u: float = 5.0
    solver_eps: float = 1e-8


#: the defaults (measured in docs/gait-design.md)
DEFAULT_CONFIG = ContactClfConfig()


@dataclass(frozen=True)
class StanceModel:
    """The gait's walker against the stance phase (one stance as the model walks it, the
    samples of contact-pd's stance table): ``domain`` (n,) codes; ``q``, ``qd`` (n, nq);
    ``wrench`` (n, 4) the contact wrenches of each sample's domain, zero-padded (N, N m)."""

    phase: np.ndarray
    domain: np.ndarray
    q: np.ndarray
    qd: np.ndarray
    wrench: np.ndarray

    def at(self, s: float) -> tuple[Domain, np.ndarray, np.ndarray, np.ndarray]:
        """(domain, q, qd, wrench) at phase ``s``: the domain of the sample at or
        before it, linear to the next sample within that domain (copies)."""
        ph = self.phase
        i = min(max(int(np.searchsorted(ph, s, side="right")) - 1, 0), ph.size - 1)
        j = min(i + 1, ph.size - 1)
        code = int(self.domain[i])
        w = 0.0
        if j != i and int(self.domain[j]) == code and ph[j] > ph[i]:
            w = min(max((s - ph[i]) / (ph[j] - ph[i]), 0.0), 1.0)
        q, qd, wrench = ((1.0 - w) * a[i] + w * a[j] for a in (self.q, self.qd, self.wrench))
        return Domain.from_code(code), q, qd, wrench


def joint_clf(eps: float) -> np.ndarray:
    """P_eps of the two joints' RES-CLF: eta = (e_k, e_a, de_k, de_a), eta_dot = F eta + G nu,
    CARE with Q = I, R = I, positions scaled by 1/eps."""
    F = np.block([[np.zeros((2, 2)), np.eye(2)], [np.zeros((2, 2)), np.zeros((2, 2))]])
    G = np.vstack([np.zeros((2, 2)), np.eye(2)])
    P = solve_continuous_are(F, G, np.eye(4), np.eye(2))
    P = 0.5 * (P + P.T)
    scale = np.diag([1.0 / eps, 1.0 / eps, 1.0, 1.0])
    return scale @ P @ scale


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


class ContactClfQp:
    """The controller of the module docstring, one tick per measurement: motor torques
    (knee, ankle; N m) clamped to the motors' limits."""

    name = "clfqp"

    def __init__(self, phase_law: ContactPhasePD, walker: StanceModel,
                 interaction: FunctionSet, thetas: Mapping[Domain, np.ndarray],
                 gains: tuple[float, float, float], model: HumanProsthesisModel,
                 config: ContactClfConfig = DEFAULT_CONFIG) -> None:
        self.law, self.walker, self.config = phase_law, walker, config
        self._fns = {d: interaction[f"interaction_{d}"] for d in STANCE_DOMAINS}
        self._thetas = {d: np.asarray(thetas[d], float) for d in STANCE_DOMAINS}
        self._gains = np.asarray(gains, float)
        self._joints = [model.coord_names.index(c) for c in PROSTHESIS]
        self._weight = float(model.tree.total_mass) * 9.81
        self._soles = soles(model)
        self._P = joint_clf(config.eps)
        p = model.device.prosthesis
        self._limits = np.array([p.knee.torque_limit.value, p.ankle.torque_limit.value])
        self._rows = 1 + 5 * 2  # the CLF, then at most two contacts of five rows
        self._solver = dense_solver(
            config.solver_eps, P=np.eye(4), c=np.zeros(4),
            G=np.ones((self._rows, 4)), h_l=np.full(self._rows, -math.inf),
            h_u=np.ones(self._rows), x_l=-np.ones(4), x_u=np.ones(4))
        self.reset()

    def reset(self) -> None:
        self.law.reset()
        self._u = np.zeros(2)
        #: the last stance tick's domain (as the gait has it at the phase; None in swing), the
        #: CLF's value, the relaxations and whether piqp solved it
        self.domain: Domain | None = None
        self.V = self.rho = self.sigma = 0.0
        self.solved = True
        #: the last stance QP as piqp got it: (P, c, G, h, x_l, x_u), min 1/2 z^T P z + c^T z,
        #: G z <= h, x_l <= z <= x_u
        self.qp: tuple[np.ndarray, ...] | None = None

    @property
    def phase(self) -> float:
        return self.law.phase

    def tick(self, m: ProsthesisMeasurement) -> tuple[float, float]:
        fields = (m.t, m.knee_angle, m.ankle_angle, m.knee_vel, m.ankle_vel, m.socket_pitch)
        if not all(math.isfinite(v) for v in fields):
            self._u[:] = 0.0
            return 0.0, 0.0
        fallback = self.law.tick(m)  # the phase, the swing law and the fallback
        if not m.contact:
            self.domain = None
            self._u[:] = fallback
            return fallback
        u = self._stance(m, self.law.phase)
        if u is None:
            u = np.asarray(fallback, float)
        u = np.clip(u, -self._limits, self._limits)
        self._u[:] = u
        return float(u[0]), float(u[1])

    def _stance(self, m: ProsthesisMeasurement, s: float) -> np.ndarray | None:
        cfg = self.config
        d, q, qd, w_ref = self.walker.at(s)
        ref = self.law.tables.stance.at(s)
        _, g, _, W = (np.array(a) for a in self._fns[d](q, qd, self._thetas[d], self._gains))
        u_ref = ref[4:6]
        n_w = wrench_size(d)
        # in du = u - u_ref: nu = g du, w = w_ref + W du (module docstring)
        eta = np.array([m.knee_angle - ref[0], m.ankle_angle - ref[1],
                        m.knee_vel - ref[2], m.ankle_vel - ref[3]])
        Pe = self._P @ eta
        V = float(eta @ Pe)
        LfV = 2.0 * float(Pe[:2] @ eta[2:])  # the CLF's rate at du = 0
        LgV = 2.0 * Pe[2:] @ g
        Wn, wn = W / self._weight, w_ref[:n_w] / self._weight  # body weights
        H = g.T @ g + cfg.w_force * Wn.T @ Wn + cfg.w_torque * np.eye(2)
        P = np.zeros((4, 4))
        P[:2, :2] = 2.0 * H
        P[2, 2] = P[3, 3] = 1e-9
        c = np.r_[-2.0 * H @ u_ref, cfg.c_rho, cfg.c_sigma]
        G = np.zeros((self._rows, 4))
        h = np.ones(self._rows)  # unused rows: 0 <= 1
        scale = max(float(np.linalg.norm(LgV)), 1e-9)
        G[0, :2], G[0, 2] = LgV / scale, -1.0 / scale
        h[0] = (-cfg.gamma / cfg.eps * V - LfV + LgV @ u_ref) / scale
        r = 1
        for row_u, row_h in self._contact_rows(d, Wn, wn - Wn @ u_ref, wn):
            G[r, :2], G[r, 3], h[r] = row_u, -1.0, row_h
            r += 1
        du, lim = cfg.delta_u, self._limits
        x_l = np.r_[np.maximum(self._u - du, -lim), 0.0, 0.0]
        x_u = np.r_[np.minimum(self._u + du, lim), math.inf, 1.0]
        self.qp = (P, c, G, h, x_l, x_u)
        sol = self._solver
        sol.update(P=P, c=c, G=G, h_u=h, x_l=x_l, x_u=x_u)
        status = sol.solve()
        if status != piqp.PIQP_SOLVED:
            set_tolerance(sol, 100.0 * cfg.solver_eps)
            status = sol.solve()
            set_tolerance(sol, cfg.solver_eps)
        self.domain, self.V = d, V
        self.solved = status == piqp.PIQP_SOLVED
        if not self.solved:
            return None
        z = sol.result.x
        self.rho, self.sigma = float(z[2]), float(z[3])
        return np.array(z[:2])

    def _contact_rows(self, d: Domain, W: np.ndarray, w0: np.ndarray, w_ref: np.ndarray
                      ) -> list[tuple[np.ndarray, float]]:
        """The contact rows (a u <= b, before the slack) of ``d``'s contacts, the wrench
        w = w0 + W u in body weights (per contact (F_x, F_z[, M_y]) in contact order) and
        the gait's ``w_ref`` for the contacts' f_min."""
        cfg, rows, k = self.config, [], 0
        for contact in d.contacts:
            x, z = k, k + 1
            f_min = min(cfg.f_min / self._weight, 0.5 * max(float(w_ref[z]), 0.0))
            rows += [(W[x] - cfg.mu * W[z], cfg.mu * w0[z] - w0[x]),
                     (-W[x] - cfg.mu * W[z], cfg.mu * w0[z] + w0[x]),
                     (-W[z], w0[z] - f_min)]
            if contact.is_flat:  # the centre of pressure -M_y / F_z on the sole
                sole, m = self._soles[contact.side], k + 2
                rows += [(-(sole.toe * W[z] + W[m]), sole.toe * w0[z] + w0[m]),
                         (-(sole.heel * W[z] - W[m]), sole.heel * w0[z] - w0[m])]
            k += contact.size
        return rows
