"""Why a prosthesis controller built on the reduced model does or does not hold the full
loop: the input authority of the prosthesis torque on the paper's outputs, in the reduced
5-DOF subsystem (socket force F_s an input, held fixed) and in the full 12-DOF loop (the
human tracking its outputs by feedback linearization, so F_s reacts to the torque).

Outputs as the controller's (``prosthesis_controller.terms``): y1 = c_k dth_pk + c_a dth_pa
- v_hip*, y2 = th_pk - B_pk(tau).  Their derivatives (dy1, d2y2) are affine in the motor
torque u_p in both models; the authority is the 2x2 matrix d(dy1, d2y2)/du_p (per motor
N m), evaluated at states of the gait's ps collocation trajectory:

    reduced:  A_m = [L_gm y1; L_gm L_f y2]                 (the CLF-QP's ``Am``)
    full:     A   = d(dy1, d2y2)/du_p  with the prosthesis accelerations from the human's
                    feedback linearization and the constrained dynamics (``xdot_human_ps``)

and A = A_m + A_s dF_s/du_p: the difference is the socket force's response to the torque,
which the paper's robust CLF-QP treats as an exogenous disturbance inside the tube.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from hp_model.closed_loop import ClosedLoop
from hp_model.domains import Domain
from hp_model.gait_artifact import Gait
from hp_model.human_prosthesis import HumanProsthesisModel
from hp_model.outputs import stance_outputs
from prosthesis_controller import ControllerContext


def _full_output_accel(cl: ClosedLoop, gait: Gait, x: np.ndarray, u_p: np.ndarray
                       ) -> tuple[np.ndarray, np.ndarray]:
    """(dy1, d2y2) of the controller's outputs (:func:`hp_model.outputs.stance_outputs`)
    and F_s of the full loop at x under u_p."""
    vc, p = cl.paper_constraints(Domain.PS), gait.params[Domain.PS]
    r, nq = vc.roles, cl.model.nq
    xd, _, lam = cl.numeric()["xdot_human_ps"](x, gait.theta(Domain.PS), gait.gains_array, u_p)
    q, qd, qdd = x[:nq], x[nq:], xd[nq:]
    k = r.prosthesis_rows[0]
    o = stance_outputs(vc.hip, (q[r.knee], q[r.ankle], qd[r.knee], qd[r.ankle]),
                       p.alpha[k:k + 1], p.v_hip, p.p_min, p.p_max,
                       accel=(qdd[r.knee], qdd[r.ankle]))
    return np.array([float(o.dy1), float(np.ravel(o.ddy2)[0])]), lam[3:6].copy()


def input_authority(model: HumanProsthesisModel, gait: Gait, ctx: ControllerContext,
                    taus: tuple[float, ...] = (0.25, 0.5, 0.75)) -> list[dict[str, Any]]:
    """At the gait's ps collocation states nearest to ``taus``: the reduced model's A_m and
    A_s, the full loop's A and dF_s/du_p (module docstring), and the ratio of their
    Frobenius norms; the sign agreement is sign(A) == sign(A_m) entry by entry."""
    cl = ClosedLoop(model, gait.degree)
    tr = gait.trajectory[Domain.PS]
    q, qd = np.asarray(tr["q"], float), np.asarray(tr["qd"], float)
    tau_all = cl.paper_constraints(Domain.PS).phase(q, gait.params[Domain.PS])
    pk, pa = model.roles[Domain.PS].prosthesis
    f = ctx.terms.numeric["clf_qp"]
    out_names = f.function.name_out()
    rows = []
    for tau in taus:
        k = int(np.argmin(np.abs(tau_all - tau)))
        x = np.r_[q[:, k], qd[:, k]]
        a0, f0 = _full_output_accel(cl, gait, x, np.zeros(2))
        cols, dfs = [], []
        for e in np.eye(2):
            a1, f1 = _full_output_accel(cl, gait, x, e)
            cols.append(a1 - a0)  # exact: affine in u_p
            dfs.append(f1 - f0)
        A = np.column_stack(cols)
        terms = dict(zip(out_names, (np.array(o) for o in
                                     f(np.r_[q[pk, k], q[pa, k], qd[pk, k], qd[pa, k]],
                                       ctx.clf_params)), strict=True))
        Am, As = terms["Am"].reshape(2, 2), terms["As"].reshape(2, 3)
        rows.append({
            "tau": float(tau_all[k]),
            "full_A_per_motor_Nm": A.tolist(),
            "reduced_Am_per_motor_Nm": Am.tolist(),
            "reduced_As_per_N": As.tolist(),
            "dFs_du_full_N_per_motor_Nm": np.column_stack(dfs).tolist(),
            "norm_ratio_reduced_over_full": float(np.linalg.norm(Am) / np.linalg.norm(A)),
            "sign_agreement": np.equal(np.sign(A), np.sign(Am)).tolist(),
        })
    return rows
