"""A human-like gait template (rad; hip flexion negative, knee flexion positive) used as the
data targets of test gaits."""

from __future__ import annotations

import numpy as np

from characterization.gait.bezier_fit import fit_bezier
from characterization.gait.phzd import DataTargets


def template_targets() -> DataTargets:
    t = np.linspace(0, 1, 101)

    def ramp(a, b, bump=0.0):
        return a + (b - a) * t + bump * np.sin(np.pi * t)

    swing = [ramp(0.25, -0.35), ramp(0.6, 0.05, 0.6), ramp(0.0, 0.3)]
    stance_hip, stance_knee = ramp(-0.25, 0.10), ramp(0.05, 0.05, 0.05)
    ps = np.c_[swing[0], swing[1], swing[2], stance_hip, stance_knee]
    pns = np.c_[stance_hip, stance_knee, swing[0], swing[1], swing[2]]
    return DataTargets(alpha={"ps": fit_bezier(t, ps, 5).alpha, "pns": fit_bezier(t, pns, 5).alpha},
                       v_hip={"ps": 1.0, "pns": 1.0}, p_min={"ps": -0.15, "pns": -0.15},
                       p_max={"ps": 0.15, "pns": 0.15})
