"""Online estimate of the model error d and the coverage monitor of ``clfqp`` (issue 17; the
paper's future work).

The interaction-aware controller's model says the output accelerations are
nu = a(x) + A(x) u (x = x_p, u the motor torques; :mod:`hp_model.interaction`).  From the
prosthesis's own measurements, per stance tick k (times t_k, the torque u_{k-1} held over
[t_{k-1}, t_k]):

    ddth_k  = (v_k - v_{k-1}) / (t_k - t_{k-1})                  measured joint velocities
    d_raw_k = b(x_{k-1}) + Jv(x_{k-1}) ddth_k - A(x_{k-1}) u_{k-1}   (b = Jo[:, :2] dth - a)
    d_hat_k = d_hat_{k-1} + dt / (T_f + dt) (d_raw_k - d_hat_{k-1})  (first sample: d_raw)

i.e. the measured output accelerations Jo (dth, ddth) minus the model's, both at the state
the interval started from, low-passed causally (time constant T_f, ``UncertaintyConfig.
filter_time``).  Units: d = (dy1 [m/s^2], d2y2 [rad/s^2]).  Errors against the true d(t_k):
the finite difference is the mean acceleration over the interval (O(dt |d nu/dt|)), the
filter lags a ramp by T_f (|d_hat - d| <= T_f max|dd/dt| + (dt/2) max|dnu/dt| after a few
T_f), and velocity quantization q_v adds about |Jv| q_v / dt per raw sample, reduced by the
filter to |Jv| q_v / dt sqrt(dt / (2 T_f)).

The estimator restarts (no finite difference) at the first stance tick, after a swing or a
faulty tick, after a gap longer than ``max_dt`` (a lost cycle) and on a non-finite value;
until it has run for 3 T_f its estimate is not ``valid``.  Monitor: a valid estimate outside the
characterised bound [lo - tol, hi + tol] (the tube's ``model_error`` at x_{k-1}, where it is
defined: in its phase range and past the excluded time after touchdown) raises the flag and
counts the tick.  With no bound in the tube nothing is ever flagged.  Every output is finite.
"""

from __future__ import annotations

import math


class DisturbanceEstimator:
    """State of the estimator and the monitor (module docstring); plain floats, no
    allocation per tick."""

    __slots__ = (
        "_T",
        "_max_dt",
        "_n",
        "_prev",
        "_t",
        "_tol0",
        "_tol1",
        "_v0",
        "_v1",
        "_warm",
        "count",
        "d0",
        "d1",
        "flag",
        "valid",
    )

    def __init__(self, filter_time: float, max_dt: float, tolerance: tuple[float, float]
                 ) -> None:
        self._T = float(filter_time)
        self._max_dt = float(max_dt)
        self._tol0, self._tol1 = float(tolerance[0]), float(tolerance[1])
        self._warm = 3.0 * self._T
        self.reset()

    def reset(self) -> None:
        """Forget everything, the count included."""
        self.restart()
        self.count = 0

    def restart(self) -> None:
        """No previous sample: the next tick only stores its terms."""
        self._prev: list[float] | None = None
        self._t = self._v0 = self._v1 = 0.0
        self._n = 0.0  # time the filter has run (s)
        self.d0 = self.d1 = 0.0
        self.valid = self.flag = False

    def update(self, t: float, v0: float, v1: float, u0: float, u1: float,
               monitored: bool) -> None:
        """One stance tick at time t (s) with the measured joint velocities (v0, v1) (rad/s)
        and the torques (u0, u1) (motor N m) held since the previous tick; ``monitored``:
        whether the previous tick's state is where the bound is defined.  Uses the previous
        tick's terms (:meth:`store`)."""
        p = self._prev
        self.flag = False
        dt = t - self._t
        if p is None or not 0.0 < dt <= self._max_dt:
            self.restart()
            return
        a0, a1 = (v0 - self._v0) / dt, (v1 - self._v1) / dt
        r0 = p[0] + p[2] * a0 + p[3] * a1 - p[6] * u0 - p[7] * u1
        r1 = p[1] + p[4] * a0 + p[5] * a1 - p[8] * u0 - p[9] * u1
        if not (math.isfinite(r0) and math.isfinite(r1)):
            self.restart()
            return
        if self._n == 0.0:
            self.d0, self.d1 = r0, r1
        else:
            g = dt / (self._T + dt)
            self.d0 += g * (r0 - self.d0)
            self.d1 += g * (r1 - self.d1)
        self._n += dt
        self.valid = self._n >= self._warm
        if monitored and self.valid and p[14] > 0.5:
            d0, d1 = self.d0, self.d1
            if (d0 < p[10] - self._tol0 or d0 > p[12] + self._tol0
                    or d1 < p[11] - self._tol1 or d1 > p[13] + self._tol1):
                self.flag = True
                self.count += 1

    def store(self, t: float, v0: float, v1: float, terms: list[float]) -> None:
        """This tick's time, velocities and model terms (``terms.ESTIMATOR_TERMS``, at the
        measured state) for the next :meth:`update`."""
        self._t, self._v0, self._v1, self._prev = t, v0, v1, terms
