"""Static equilibrium of a constrained model: the torques and constraint wrenches that hold a
posture still.

At rest (qd = qdd = 0) the dynamics reduce to G(q) = B u + J^T lam.  With as many
actuators plus constraints as coordinates (the human-prosthesis model in single support:
6 + 6 = 12) the square system [B  J^T] [u; lam] = G fixes both.
"""

from __future__ import annotations

import numpy as np

from hp_model.hybrid import HybridModel


def standing_posture(model: HybridModel, hip_height: float | None = None) -> np.ndarray:
    """Upright posture (all angles zero) with both soles on the ground, base above the origin."""
    q = np.zeros(model.nq)
    if hip_height is None:
        fs = model.numeric()
        poses, _ = fs["frames"](q, np.zeros(model.nq))
        soles = [model.frame_index(f) for f in model.frame_names if f.endswith("_sole")]
        hip_height = -float(np.min(poses[1, soles]))
    q[model.coord_names.index("z_B")] = hip_height
    return q


def static_equilibrium(
    model: HybridModel, domain: str, q: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """(u, lam) holding posture ``q`` still in ``domain`` (least squares if not square)."""
    fs = model.numeric()
    qd = np.zeros(model.nq)
    _, H, J, _ = fs[f"terms_{domain}"](q, qd)
    A = np.hstack([model.B, J.T])
    sol, *_ = np.linalg.lstsq(A, H, rcond=None)
    return sol[: model.nu].copy(), sol[model.nu :].copy()
