"""The FMU's initial state, mirrored in Python (the C code in ``hpfmu.c`` does the same
arithmetic on the same generated functions).

With zero prosthesis offsets the initial state is (q0, qd0) unchanged.  Otherwise the knee
and ankle offsets are added to th_pk and th_pa, and when the prosthesis foot is the stance
foot (domain ps) the walker is re-placed so that foot stays flat where it was: the floating
base is reset to zero, rotated so the foot pitch is zero, and shifted so the sole is back at
its original (x, z); the velocities are then projected onto the stance and socket
constraints with the domain's impact map (the D-metric projection, so J qd = 0 again).  In
pns the prosthesis is the swing leg and no constraint involves its joints.
"""

from __future__ import annotations

import numpy as np

from hp_model.human_prosthesis import HumanProsthesisModel

KNEE, ANKLE = "th_pk", "th_pa"


def initial_state(model: HumanProsthesisModel, q0: np.ndarray, qd0: np.ndarray, domain: str,
                  offset_knee: float = 0.0, offset_ankle: float = 0.0
                  ) -> tuple[np.ndarray, np.ndarray]:
    """(q, qd) the FMU starts from, given its parameters (see the module docstring)."""
    q = np.array(q0, dtype=float)
    qd = np.array(qd0, dtype=float)
    if offset_knee == 0.0 and offset_ankle == 0.0:
        return q, qd
    fs = model.numeric()
    frames = fs["frames"]
    zero = np.zeros(model.nq)
    q[model.coord_names.index(KNEE)] += offset_knee
    q[model.coord_names.index(ANKLE)] += offset_ankle
    if domain == "ps":
        i = model.frame_index(model.stance_frame(domain))
        pose = frames(np.asarray(q0, dtype=float), zero)[0]
        x_f, z_f = float(pose[0, i]), float(pose[1, i])
        q[0:3] = 0.0
        q[2] = -frames(q, zero)[0][2, i]
        pose = frames(q, zero)[0]
        q[0] = x_f - pose[0, i]
        q[1] = z_f - pose[1, i]
        qd = fs[f"impact_{domain}"](q, qd)[0].copy()
    return q, qd
