"""The multi-contact gait as virtual constraints: what the simulated human and the walker
track (:mod:`hp_model.contact_outputs`), regressed from the fitted trajectory
(:mod:`characterization.gait.multicontact`).

Per domain d: the hip progress over its reference contact p(q_k) at the fitted nodes sets
p_min, p_max (its first and last node) and each node's phase tau_k; the y2 joints' angles
and, where the domain has a velocity output, the hip progress rate at the nodes are fitted
by Bezier polynomials of tau (least squares on the values and the slopes,
:func:`fit_with_rates`: a joint's slope from its rate, qd / tau_dot; the hip rate's by
finite differences of the rates over tau, never from the fitted accelerations: when the fit
held its contacts at the position level its accelerations need not satisfy them and zigzagged
from node to midpoint, e.g. the stance ankle's, which the hip progress over the stance foot
sums: -35 and +15 m/s^2 alternating on openOFM's fit while the hip's own acceleration stayed
within 2.5 m/s^2, and the hip-rate curve missed the rates by 0.1 m/s RMS); v_hip is the mean
hip progress rate (p_max - p_min) / T_d; in a double support the leading contact's friction
ratio F_x / F_z (the legs' squeeze, :mod:`hp_model.contact_outputs`) from the fit's wrenches
where it is loaded.  The phase must rise through the domain (the hip moving forward over
the contact): a fitted trajectory whose hip stalls or runs back is refused.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from characterization.gait.multicontact import (
    GRAPH,
    MultiContactError,
    MultiContactResult,
    body_weight,
)
from hp_model import bezier
from hp_model.closed_loop import ClosedLoop
from hp_model.contact_outputs import ContactConstraints, selection
from hp_model.domains import Domain
from hp_model.human_prosthesis import HumanProsthesisModel
from hp_model.outputs import GaitParams
from hp_model.simulator import HybridSimulator, Policy, SimState

#: the Bezier degree of the multi-contact gait's curves
DEGREE = 5
#: the weight of a node's slope dB/dtau against its value in the regression (per unit tau)
RATE_WEIGHT = 0.1


@dataclass(frozen=True)
class ContactGait:
    """The virtual constraints of each domain (:class:`GaitParams`: alpha (rows, m+1): the
    y2 joints' curves (rad), then the hip rate's (m/s) where there is one, then in a double
    support the leading contact's friction ratio F_x / F_z; v_hip m/s, p_min and p_max m) and
    the regression's RMS residual per row (rad, m/s, 1)."""

    params: dict[Domain, GaitParams]
    rms: dict[Domain, np.ndarray]

    def thetas(self) -> dict[Domain, np.ndarray]:
        """The packed vectors the closed loop takes."""
        return {d: p.pack() for d, p in self.params.items()}

    def to_json(self) -> dict[str, Any]:
        """Per domain: its outputs' joints, whether it has the hip-rate row, the curves
        (alpha rows: the joints' (rad), then the hip rate's (m/s)), v_hip, p_min, p_max, the
        phase's reference frame and the regression's RMS per row."""
        return {d.value: {"y2_coords": list(d.y2_coords), "velocity_output": d.velocity_output,
                          "squeeze_output": d.is_double_support,
                          "reference_frame": d.contacts[0].frame, "alpha": p.alpha,
                          "v_hip": p.v_hip, "p_min": p.p_min, "p_max": p.p_max,
                          "rms": self.rms[d]}
                for d, p in self.params.items()}


def contact_gait(model: HumanProsthesisModel, result: MultiContactResult,
                 degree: int = DEGREE) -> ContactGait:
    """The virtual constraints of the fitted cycle ``result`` (module docstring)."""
    return contact_gait_of(model, result.trajectory, result.durations, degree)


def contact_gait_of(model: HumanProsthesisModel,
                    trajectory: Mapping[Domain, Mapping[str, Any]],
                    durations: Mapping[Domain, float], degree: int = DEGREE) -> ContactGait:
    """The virtual constraints of a fitted cycle given as its per-domain trajectories (``q``,
    ``qd`` (12, P) at the nodes, and in a double support ``lam`` (N, Domain.contacts order);
    the accelerations are not read) and durations (s): a fit's or a gait file's."""
    params: dict[Domain, GaitParams] = {}
    rms: dict[Domain, np.ndarray] = {}
    for d in GRAPH.domains:
        vc = ContactConstraints(model, d, degree)
        tr = trajectory[d]
        q, qd = np.asarray(tr["q"], float), np.asarray(tr["qd"], float)
        pp = [vc.progress(q[:, k], qd[:, k]) for k in range(q.shape[1])]
        p = np.array([float(a) for a, _ in pp])
        p_dot = np.array([float(b) for _, b in pp])
        if not np.all(np.diff(p) > 0):
            k = int(np.argmin(np.diff(p)))
            raise MultiContactError(
                f"domain {d}: the hip does not move forward over its {vc.reference_frame} "
                f"throughout (node {k}: {p[k]:.4f} -> {p[k + 1]:.4f} m); no phase variable")
        step = p[-1] - p[0]
        tau, tau_dot = (p - p[0]) / step, p_dot / step
        S = selection(model, d.y2_coords)
        rows, slopes = (S @ q).T, (S @ qd).T / tau_dot[:, None]  # qd = B' tau_dot
        if d.velocity_output:  # the hip rate's curve; its slope from the rates themselves
            rows = np.c_[rows, p_dot]
            slopes = np.c_[slopes, np.gradient(p_dot, tau, edge_order=2)]
        alpha = fit_with_rates(tau, rows, slopes, degree)
        rms[d] = np.sqrt(np.mean((bezier.basis(degree, tau) @ alpha.T - rows) ** 2, axis=0))
        if d.is_double_support:  # the squeeze: the leading contact's friction ratio
            ratio, ratio_rms = _friction_ratio(np.asarray(tr["lam"], float), tau, degree,
                                               LOADED * body_weight(model))
            alpha, rms[d] = np.r_[alpha, ratio[None, :]], np.r_[rms[d], ratio_rms]
        params[d] = GaitParams(alpha, step / durations[d], float(p[0]), float(p[-1]))
    return ContactGait(params, rms)


#: body weights: a contact's normal force above which its friction ratio F_x / F_z is read
#: (at the heel strike both start from zero)
LOADED = 0.02


def _friction_ratio(lam: np.ndarray, tau: np.ndarray, degree: int, loaded: float
                    ) -> tuple[np.ndarray, float]:
    """The Bezier coefficients (m+1,) of the leading contact's F_x / F_z over a double
    support (``lam`` (n_c, n) in N, its first rows the leading contact's F_x, F_z), least
    squares on the nodes where F_z > ``loaded`` (N), and the fit's RMS residual there."""
    fx, fz = lam[0], lam[1]
    on = fz > loaded
    if on.sum() <= degree:
        raise MultiContactError(f"the double support's leading contact carries more than "
                                f"{loaded:.0f} N at {on.sum()} nodes only (need {degree + 1})")
    H = bezier.basis(degree, tau[on])
    r = fx[on] / fz[on]
    coef, *_ = np.linalg.lstsq(H, r, rcond=None)
    return coef, float(np.sqrt(np.mean((H @ coef - r) ** 2)))


def fit_with_rates(tau: np.ndarray, y: np.ndarray, dy: np.ndarray, degree: int,
                   rate_weight: float = RATE_WEIGHT) -> np.ndarray:
    """alpha (rows, m+1) of the Bezier curves B with B(tau_k) ~ y_k and dB/dtau(tau_k) ~
    dy_k (y, dy: (n, rows)), least squares, the slopes weighted by ``rate_weight``: the
    slopes hold the curves' ends (where the nodes alone leave a polynomial free to bend, and
    the closed loop would follow the bend with forces the gait never had).  (The nodes'
    accelerations as a third set of rows made it worse: the collocation's accelerations
    zigzag between nodes and midpoints.)"""
    H = bezier.basis(degree, tau)
    diff = degree * (np.eye(degree + 1, k=1) - np.eye(degree + 1))[:-1]  # (m, m+1)
    Hd = bezier.basis(degree - 1, tau) @ diff
    coef, *_ = np.linalg.lstsq(np.r_[H, rate_weight * Hd], np.r_[y, rate_weight * dy],
                               rcond=None)
    return coef.T


def start_state(trajectory: Mapping[Domain, Mapping[str, Any]],
                domain: Domain = GRAPH.domains[0]) -> tuple[np.ndarray, np.ndarray]:
    """(q, qd) of a fitted cycle's trajectories at the start of ``domain``."""
    tr = trajectory[domain]
    return np.asarray(tr["q"], float)[:, 0].copy(), np.asarray(tr["qd"], float)[:, 0].copy()


#: the simulated human's gains (eps 1/s, kp 1/s^2, kd 1/s): the paper's gaits' kp and kd;
#: eps twice theirs, so that an error of the hip's rate settles within a domain (the toe
#: and double-support domains last 0.11-0.14 s; 1/eps = 0.05 s).  Measured on openOFM's
#: fit: a heel strike's new contact starts from no force, and with eps 10 the heel was
#: outside the simulator's cone (mu 0.8) for 3-4 of the 5 ms it allows after each heel
#: strike of the prosthesis, with 20 for at most 1; at 30 it left the cone at ds_h
GAINS = (20.0, 1600.0, 80.0)


@dataclass(frozen=True)
class ContactWalk:
    """The fitted cycle walked in closed loop: the steps taken (heel strikes), how the run
    ended (``fall``: its one-line message, None if it took every step), each stride's time
    (s, heel strike to heel strike of the human foot) and speed (m/s) after the first."""

    steps: int
    wanted: int
    fall: str | None
    strides: np.ndarray
    speeds: np.ndarray
    #: how the human and the prosthesis were run
    controller: str = ""

    @property
    def walks(self) -> bool:
        return self.fall is None and self.steps >= self.wanted

    def to_json(self) -> dict[str, Any]:
        return {"walks": self.walks, "steps": self.steps, "wanted": self.wanted,
                "fall": self.fall, "strides": self.strides, "speeds": self.speeds,
                "controller": self.controller or HELD_ORACLE}

    def line(self) -> str:
        """One line: the verdict and how it was run."""
        how = self.controller or HELD_ORACLE
        if not self.walks:
            return f"does not walk: after {self.steps} steps, {self.fall} ({how})"
        return (f"walks {self.steps} steps: stride {np.median(self.strides):.3f} s, "
                f"{np.median(self.speeds):.3f} m/s ({how})")


#: how :func:`walk_contact_gait` runs the prosthesis
HELD_ORACLE = ("the human on feedback linearization of the fitted gait, the prosthesis "
               "holding that law's torque over each 1 ms period within its motor limits")


def feedback_within_limits(u_ff: np.ndarray, u_fb: np.ndarray, share: float,
                           limits: np.ndarray) -> np.ndarray:
    """The torque u_ff + s u_fb (N m) with the largest feedback share s in [0, ``share``] that
    keeps every torque within +-``limits``; a feedforward torque past its limit alone is
    clamped.  Cutting the share keeps the feedback's direction, where clamping one torque
    would turn it (a law of coupled outputs: the other torque then corrects for it)."""
    s = share
    for j, lim in enumerate(limits):
        u = u_ff[j] + s * u_fb[j]
        if abs(u) > lim and u_fb[j] != 0.0:
            s = min(s, max(0.0, (math.copysign(lim, u) - u_ff[j]) / u_fb[j]))
    return np.clip(u_ff + s * u_fb, -limits, limits)


def held_oracle(closed_loop: ClosedLoop, thetas: Mapping[Domain, np.ndarray],
                gains: np.ndarray, within_limits: bool = False) -> Policy:
    """The prosthesis policy that applies, each period, the motor torque (2, N m) the full
    feedback linearization of the gait gives at the period's start (the simulator holds it
    over the period and clamps it to the motors' limits): full-state feedback, what a
    prosthesis controller's torque is measured against.  It follows the gait the human
    tracks (the state's ``theta``, when the run has a gait schedule; else ``thetas``).

    ``within_limits``: where that torque is past a motor's limit, the law's feedback share
    is cut until both are within them (:func:`feedback_within_limits` on ``feedback_<d>``'s
    parts, as the person yields its own at its contacts); elsewhere the same torque.  The
    walkability reference of the sweeps and the perturbation experiments: clamped, the
    oracle lost a knee or ankle offset's first stance (the motors at their limits from the
    first period, the hip's rate lost, the stance foot out of its cone) where the
    controllers walked."""
    fns = {d: closed_loop.vcs[d].numeric() for d in closed_loop.model.graph.domains}
    limits = np.asarray(closed_loop.model.torque_limits[4:6], float)

    def policy(_t: float, st: SimState) -> np.ndarray:
        theta = thetas[st.domain] if st.theta is None else st.theta  # the human's, now
        u = np.asarray(fns[st.domain][f"fl_{st.domain}"](st.q, st.qd, theta, gains)[0]
                       ).ravel()[4:6]
        if not within_limits or np.all(np.abs(u) <= limits):
            return u
        u_ff, u_fb, share = (np.array(a, float).ravel() for a in
                             fns[st.domain][f"feedback_{st.domain}"](st.q, st.qd, theta, gains))
        return feedback_within_limits(u_ff[4:6], u_fb[4:6], float(share[0]), limits)

    return policy


def walk_contact_gait(model: HumanProsthesisModel, gait: ContactGait,
                      trajectory: Mapping[Domain, Mapping[str, Any]], steps: int = 10,
                      gains: tuple[float, float, float] = GAINS) -> ContactWalk:
    """Simulate ``steps`` steps of ``gait`` from the fitted cycle's start (the in-process
    simulator, mode human: the prosthesis on :func:`held_oracle`) and measure them
    (:class:`ContactWalk`)."""
    cl = ClosedLoop(model, gait.params[GRAPH.domains[0]].degree)
    g = np.array(gains)
    thetas = gait.thetas()
    sim = HybridSimulator(model, cl, thetas, g)
    q0, qd0 = start_state(trajectory)
    res = sim.run(q0, qd0, GRAPH.domains[0], steps=steps, duration=2.0 * steps,
                  policy=held_oracle(cl, thetas, g))
    strikes = [i for i in res.impacts if i.into == Domain.DS_H]
    t = np.array([i.t for i in strikes])
    x = np.array([float(i.q[0]) for i in strikes])
    return ContactWalk(res.steps, steps, None if res.fall is None else res.fall.message(),
                       np.diff(t), np.diff(x) / np.diff(t) if t.size > 1 else np.array([]))
