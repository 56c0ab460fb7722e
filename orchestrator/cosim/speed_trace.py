"""The walking speed of a recorded run of a person walking a gait library (``hpcosim run
--library --speed-profile``): the speed commanded, and what the controller made of the walk,
its speed estimate, the speed of the controller it ran and its phase, given again by its
recorded measurements replayed through the recorded controller file (the run's own, tick
for tick: ``hpcosim replay`` finds no torque difference)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from orchestrator.cosim.recording import (
    RecordingError,
    read_recording,
    recorded_controller,
    recorded_measurement,
    recorded_profile,
)
from prosthesis_controller.speed_following import SpeedFollowing


@dataclass(frozen=True)
class SpeedTrace:
    """Per recorded measurement: ``t`` (n,) s; ``command`` (n,) m/s, the speed commanded;
    the controller's ``estimate`` (n,) m/s after its tick, the speed of the controller it
    ran (``running``, m/s) and its ``phase`` (n,) (stance: the hip's progress over the
    foot, 0-1; swing: its swing phase)."""

    t: np.ndarray
    command: np.ndarray
    estimate: np.ndarray
    running: np.ndarray
    phase: np.ndarray

    def at(self, t: np.ndarray) -> SpeedTrace:
        """The trace at times ``t`` (s): each the measurement of the same period (NaN where
        none was recorded)."""
        key = {round(float(s) * 1e6): i for i, s in enumerate(self.t)}
        rows = [key.get(round(float(s) * 1e6), -1) for s in np.asarray(t, float)]
        idx, have = np.array(rows), np.array(rows) >= 0

        def pick(x: np.ndarray) -> np.ndarray:
            return np.where(have, x[np.maximum(idx, 0)], np.nan)

        return SpeedTrace(np.asarray(t, float), pick(self.command), pick(self.estimate),
                          pick(self.running), pick(self.phase))


def speed_trace(path: str | Path) -> SpeedTrace | None:
    """The trace of the recording ``path`` (module docstring); None for a recording of any
    other run.  RecordingError naming the file when its speed metadata or controller file
    is damaged."""
    rec = read_recording(path)
    profile = recorded_profile(rec)
    if profile is None:
        return None
    ctl = recorded_controller(rec)
    if not isinstance(ctl, SpeedFollowing):
        raise RecordingError(f"{rec.path}: its controller file is not a gait library's "
                             "(speed following)")
    ctl.reset()
    rows = []
    for m in rec.measurements:
        meas = recorded_measurement(m)
        ctl.tick(meas)
        rows.append((meas.t, profile.at(meas.t), ctl.speed, ctl.speeds[ctl.active],
                     ctl.phase))
    cols = np.array(rows, float).reshape(-1, 5).T
    return SpeedTrace(*cols)


__all__ = ["SpeedTrace", "speed_trace"]
