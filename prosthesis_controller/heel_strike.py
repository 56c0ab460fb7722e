"""The person's heel strike, sensed at the prosthesis's joints while the prosthesis is on its
toe (:class:`HeelStrikeSensor`).

The person's heel strike is an impact on the closed chain: the prosthesis's knee and ankle
accelerations step away from what the stance model predicts, at once.  The residual (the
joints' measured acceleration, their speeds' change over a period, less the model's) of the
packaged person's early strikes stepped from about 0 to 170-480 rad/s^2 within one period
and stayed above 150 for several, on both joints (their signs depend on the gait: both
positive on the packaged person, knee negative and ankle positive on the committed cycle);
off a strike the residual drifts, by up to 50 rad/s^2 over the last milliseconds of
``ps_toe`` on persons whose curves are perturbed, a few rad/s^2 per period
(docs/gait-design.md, "The person's heel strike sensed at the prosthesis").  The load cell
does not show the strike: the prosthesis's toe keeps its load through it.

The sensor's statistic is the step of the residual: its mean over the last ``window``
periods less its mean over the ``window`` before them, both joints' as a vector; a strike
where its norm passes ``threshold`` and the residual moved away from the prediction (its
last mean larger than the one before).  A step back toward it is the plant catching up with
the model, not a strike: the prosthesis's own heel leaving the ground a few periods after
the controller's phase entered ``ps_toe`` (a person slower than the gait; gaitalytics'
library with the person changing speed, 7 of 200 draws fell on it when it counted).  Each
period's prediction is the caller's (the stance model under the torque applied in it).
Pure arithmetic on floats, a few per tick (the controller's tick is held to 40 us).
"""

from __future__ import annotations

import math
from collections import deque


class HeelStrikeSensor:
    """Feed :meth:`update` once per tick while the prosthesis is on its toe; it returns the
    time of the person's heel strike (s) once sensed, None until then.  ``window``: the
    periods of each of the two means (module docstring); ``threshold``: rad/s^2, the norm of
    their difference that is a strike (the sweeps' encoder noise, 0.02 rad/s white, gives
    16 rad/s^2 of standard deviation per joint at a window of 3).  :meth:`reset` at each of
    the prosthesis's own stances; :meth:`restart` where the ticks fed stop being one toe
    stance's (a tick not fed)."""

    def __init__(self, window: int = 3, threshold: float = 100.0) -> None:
        if window < 1:
            raise ValueError(f"heel strike window must be at least 1 period, got {window}")
        if not threshold > 0:
            raise ValueError(f"heel strike threshold must be > 0 rad/s^2, got {threshold}")
        self.window, self.threshold = int(window), float(threshold)
        #: (t, knee speed, ankle speed, the model's accelerations over the period that ended
        #: at t) per tick: the two windows' periods and the tick that starts them
        self._ticks: deque[tuple[float, float, float, float, float]] = deque(
            maxlen=2 * window + 1)
        self.struck_at: float | None = None

    def reset(self) -> None:
        """Forget the strike and the ticks (a new stance of the prosthesis)."""
        self._ticks.clear()
        self.struck_at = None

    def restart(self) -> None:
        """Forget the ticks, keep the strike."""
        self._ticks.clear()

    def update(self, t: float, knee_vel: float, ankle_vel: float, knee_acc: float,
               ankle_acc: float) -> float | None:
        """One tick: the measured joint speeds (rad/s) at t (s), and the model's accelerations
        (rad/s^2) over the period that ended at t, under the torque applied in it.  Returns
        :attr:`struck_at`."""
        if self.struck_at is not None:
            return self.struck_at
        ticks = self._ticks
        ticks.append((t, knee_vel, ankle_vel, knee_acc, ankle_acc))
        if len(ticks) < 2 * self.window + 1:
            return None
        m = self.window
        old, mid = ticks[0], ticks[m]
        before = self._mean_residual(old, mid, 1, m)
        after = self._mean_residual(mid, ticks[2 * m], m + 1, 2 * m)
        if before is None or after is None:
            return None
        thr = self.threshold
        away = math.hypot(*after) > math.hypot(*before)
        if away and math.hypot(after[0] - before[0], after[1] - before[1]) > thr:
            # the strike: the start of the first recent period whose own residual stepped
            self.struck_at = mid[0]
            for j in range(m + 1, 2 * m + 1):
                r = self._mean_residual(ticks[j - 1], ticks[j], j, j)
                if r is not None and math.hypot(r[0] - before[0], r[1] - before[1]) > thr:
                    self.struck_at = ticks[j - 1][0]
                    break
        return self.struck_at

    def _mean_residual(self, a: tuple[float, ...], b: tuple[float, ...], first: int,
                       last: int) -> tuple[float, float] | None:
        """The residual (rad/s^2, knee and ankle) over the periods from tick ``a`` to tick
        ``b``, whose predictions are the ticks ``first``..``last`` of the window's; None if no
        time passed."""
        dt = b[0] - a[0]
        if not dt > 0:
            return None
        n = last - first + 1
        ticks = self._ticks
        pk = sum(ticks[j][3] for j in range(first, last + 1)) / n
        pa = sum(ticks[j][4] for j in range(first, last + 1)) / n
        return (b[1] - a[1]) / dt - pk, (b[2] - a[2]) / dt - pa
