"""The prosthesis leg's geometry as AMPRO3 senses it (:class:`LegKinematics`): from the socket
IMU's pitch and the knee and ankle encoders, the hip's forward progress over the prosthesis
heel's ground point, the stance phase's measure (:mod:`prosthesis_controller.contact_phase_pd`;
the multi-contact playback, :mod:`characterization.tube.contact_playback`, reads recorded
postures by it).  One function of the model: the leg below the socket depends on nothing
else."""

from __future__ import annotations

import math

import casadi as ca
import numpy as np

from hp_model.compiled import NumericFunction
from hp_model.domains import PROSTHESIS
from hp_model.human_prosthesis import HumanProsthesisModel


class LegKinematics:
    """The prosthesis leg's geometry from what it senses: ``f`` (socket pitch, knee, ankle)
    -> (x_hip - x_heel, x_hip - x_toe, z_heel - z_toe) (m, world frame); ``heel_to_toe``:
    the sole's length between its heel and toe points (m)."""

    def __init__(self, f: ca.Function, heel_to_toe: float) -> None:
        self.f, self.heel_to_toe = f, heel_to_toe
        self._num = NumericFunction(f)  # bound to buffers: called every tick

    @classmethod
    def of(cls, model: HumanProsthesisModel) -> LegKinematics:
        ix = model.coord_names.index
        x = ca.SX.sym("x", 3)  # socket pitch, knee, ankle
        socket = model.pitch_row("socket")
        # a posture with the socket at the sensed pitch: the leg below it depends on nothing
        # else (its translation joints are held at zero)
        base = int(np.flatnonzero(socket)[0])
        sub = ca.SX.zeros(model.nq)
        sub[base], sub[ix(PROSTHESIS[0])], sub[ix(PROSTHESIS[1])] = x[0], x[1], x[2]
        hip, heel, toe = (model.frame_expr(n, sub) for n in ("hip", "p_heel", "p_toe"))
        f = ca.Function("prosthesis_leg", [x],
                        [ca.vertcat(hip[0] - heel[0], hip[0] - toe[0], heel[1] - toe[1])])
        d = np.asarray(f(np.zeros(3))).ravel()
        return cls(f, float(d[0] - d[1]))

    def sense(self, pitch: float, knee: float, ankle: float) -> tuple[float, float]:
        """The hip's forward progress (m) over the heel's ground point (module docstring) and
        the heel's rise over the toe as an angle, asin((z_heel - z_toe) / heel_to_toe) (rad;
        zero on a flat foot, whatever the IMU's bias is not)."""
        n = self._num
        n.inputs[0][:] = (pitch, knee, ankle)
        n.call_inplace()
        over_heel, over_toe, heel_above_toe = n.outputs[0].tolist()
        p = over_heel if heel_above_toe <= 0.0 else over_toe + self.heel_to_toe
        return p, math.asin(min(max(heel_above_toe / self.heel_to_toe, -1.0), 1.0))

    def progress(self, pitch: float, knee: float, ankle: float) -> float:
        """The hip's forward progress (m) over the heel's ground point (module docstring)."""
        return self.sense(pitch, knee, ankle)[0]

    def progress_of(self, model: HumanProsthesisModel, q: np.ndarray) -> np.ndarray:
        """(n,) the progress (m) of postures q (n, 12) of ``model``, as the prosthesis senses
        them (the socket's pitch, the knee and the ankle)."""
        q = np.atleast_2d(np.asarray(q, float))
        row = model.pitch_row("socket")
        ik, ia = model.coord_names.index(PROSTHESIS[0]), model.coord_names.index(PROSTHESIS[1])
        return np.array([self.progress(float(r @ row), float(r[ik]), float(r[ia])) for r in q])
