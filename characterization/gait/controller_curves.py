"""The curves the prosthesis controllers read from a gait, fitted once by ``gait fit`` from
the gait's collocation trajectory and stored in the gait artifact (section
``controller_curves``, :class:`hp_model.gait_artifact.ControllerCurves`):

- the socket pitch over the pns phase, which the swing law's gravity term and thigh lead
  read (a Bezier curve of degree :data:`SOCKET_PITCH_DEGREE`);
- the nominal stance motor torques over the ps phase, the phase-PD's feedforward (degree
  :data:`STANCE_TORQUE_DEGREE`).

A gait without a trajectory gets zero curves (upright socket, no feedforward).
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from hp_model import bezier
from hp_model.domains import Domain
from hp_model.gait_artifact import ControllerCurves
from hp_model.human_prosthesis import HumanProsthesisModel
from hp_model.outputs import GaitParams, HipProgress

#: Bezier degree of the swing's nominal socket pitch
SOCKET_PITCH_DEGREE = 5
#: Bezier degree of the phase-PD's nominal stance torque (fit RMS ~0.01 N m motor on the demo
#: gait)
STANCE_TORQUE_DEGREE = 9

#: a gait's collocation trajectory per domain: {t, q, qd, qdd, u, lam} (``Gait.trajectory``)
Trajectory = Mapping[Domain, Mapping[str, np.ndarray]]


def socket_pitch_fit(model: HumanProsthesisModel, trajectory: Trajectory,
                     degree: int = SOCKET_PITCH_DEGREE) -> np.ndarray:
    """Bezier coefficients (1, degree+1) of the socket (prosthesis top link) world pitch
    (rad) over the pns phase t / T_pns, least-squares fit to the pns collocation trajectory;
    zeros (upright) when there is none."""
    tr = trajectory.get(Domain.PNS)
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


def stance_torque_fit(model: HumanProsthesisModel, params: Mapping[Domain, GaitParams],
                      trajectory: Trajectory, degree: int = STANCE_TORQUE_DEGREE
                      ) -> np.ndarray:
    """Bezier coefficients (2, degree+1) of the nominal prosthesis MOTOR torques (knee,
    ankle; N m) over the state-based ps phase tau, least-squares fit to the ps collocation
    trajectory; zeros (no feedforward) when there is none."""
    tr = trajectory.get(Domain.PS)
    if not tr or "q" not in tr or "u" not in tr:
        return np.zeros((2, degree + 1))
    q, u = np.asarray(tr["q"], dtype=float), np.asarray(tr["u"], dtype=float)
    p, r = params[Domain.PS], model.roles[Domain.PS]
    tau = HipProgress.of(model, Domain.PS).phase(q[r.knee], q[r.ankle], p.p_min, p.p_max)
    B = bezier.basis(degree, np.clip(tau, 0.0, 1.0))
    if len(tau) <= degree:
        return np.repeat(u[4:6].mean(axis=1, keepdims=True), degree + 1, axis=1)
    coef, *_ = np.linalg.lstsq(B, u[4:6].T, rcond=None)
    return coef.T


def fit_controller_curves(model: HumanProsthesisModel, params: Mapping[Domain, GaitParams],
                          trajectory: Trajectory) -> ControllerCurves:
    """Both curves of a gait (its optimized parameters and collocation trajectory)."""
    return ControllerCurves(socket_pitch=socket_pitch_fit(model, trajectory),
                            stance_torque=stance_torque_fit(model, params, trajectory))
