"""The swing law every controller runs in ``pns`` (:class:`SwingLaw`): PD + gravity on the
swing target (the pns Bezier rows of th_pk, th_pa at the swing phase, with the landing
offset; the generated ``terms.swing_ref``), at a clock phase advanced by the thigh lead.
See the package README, "Baselines and swing".
"""

from __future__ import annotations

import math

import numpy as np

from hp_model.domains import Domain
from prosthesis_controller.context import ControllerContext


class SwingLaw:
    """The shared swing law of one controller, with its thigh-lead state."""

    def __init__(self, ctx: ControllerContext) -> None:
        sw = ctx.config.swing
        self._ref = ctx.terms.numeric["swing_ref"]
        self._ref.inputs[3][:] = ctx.swing_params
        self._kp, self._kd = np.array(sw.kp), np.array(sw.kd)
        self._gravity = 1.0 if sw.gravity else 0.0
        self._gear = np.array(ctx.gear)
        self._T = ctx.durations[Domain.PNS]
        self._table = ctx.thigh_table
        self._deadband = float(sw.lead_deadband)
        self._time_constant = float(sw.lead_time_constant)
        self.reset()

    def reset(self) -> None:
        """Forget the thigh lead (at ``reset`` and at every lift-off)."""
        self._lead = 0.0  # phase units
        self._t_lead: float | None = None  # the last swing tick

    def phase(self, t: float, t_liftoff: float, pitch: float) -> float:
        """tau_hat = (t - t_liftoff) / T_pns advanced by the thigh lead (``SwingConfig``):
        ``pitch`` is the socket IMU's world pitch (rad), NaN without one."""
        s = (t - t_liftoff) / self._T
        dt = 0.0 if self._t_lead is None else t - self._t_lead
        self._t_lead = t
        tab = self._table
        if tab is not None and tab[0][0] <= pitch <= tab[0][-1] \
                and tab[1][-1] <= s <= tab[1][0]:  # both on the branch: low-pass from 0
            s_thigh = float(np.interp(pitch, tab[0], tab[1]))
            self._lead += min(dt / self._time_constant, 1.0) * ((s_thigh - s) - self._lead)
        return s + max(self._lead - self._deadband, 0.0)

    def torque(self, t: float, t_liftoff: float, x: tuple[float, float, float, float],
               pitch: float = math.nan) -> tuple[float, float, float]:
        """(knee, ankle, tau_hat): motor torques (N m) of PD + gravity on the swing target
        at state x = (th_pk, th_pa, dth_pk, dth_pa) (rad, rad/s) and the swing phase."""
        f = self._ref
        f.inputs[0][:] = x
        f.inputs[1][0] = self.phase(t, t_liftoff, pitch)
        f.inputs[2][0] = 1.0 / self._T
        f.call_inplace()
        qd, vd, _, g, tau = f.outputs
        q, v = np.array(x[:2]), np.array(x[2:])
        u = (self._gravity * g + self._kp * (qd - q) + self._kd * (vd - v)) / self._gear
        return float(u[0]), float(u[1]), float(tau[0])
