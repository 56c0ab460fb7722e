"""The 5-DOF prosthesis subsystem (paper Sec. V, "Prosthesis Model and Dynamics").

    Dbar qbar_dd + Hbar = Bbar u_p + Jbar^T Fbar + Jbar_s^T F_s,
    Jbar qbar_dd + Jbar_dot qbar_d = 0

qbar = (x_Bp, z_Bp, th_Bp, th_pk, th_pa): a floating base at the top of the prosthesis (the
socket frame of the full model), knee, ankle.  It is the full model's subtree below the
socket, extracted from the same tree (same bodies, same parameters).  F_s enters through
Jbar_s, the body Jacobian of the base frame: F_s is a wrench at the base origin in base
axes, the same quantity the full model's socket constraint carries.

In prosthesis stance the flat foot leaves 2 DOF; with the sole held at the origin the
dynamics reduce to the 4-state form (``reduced``)

    x_p = (th_pk, th_pa, dth_pk, dth_pa),   x_p_dot = f_p(x_p) + g_p^m(x_p) u_p + g_p^s(x_p) F_s.

Functions (besides :class:`~hp_model.hybrid.HybridModel`'s, with the single domain ``ps``):

    sub_dyn(q, qd, u, F_s)      -> qdd, lam_foot      (subsystem KKT solve with socket input)
    sub_dyn_<part>(q, qd, u, F_s) -> qdd, lam_point   the same with the foot on its heel or toe
                                  (``p_heel``, ``p_toe``; built from a multi-contact model: the
                                  foot pivots on the point, 3 DOF; :meth:`contact_domain`)
    jac_socket(q)               -> Jbar_s (3 x 5)
    embed(x_p)                  -> q, qd              (foot flat at the origin)
    reduced(x_p)                -> f_p (4), g_m (4 x 2), g_s (4 x 3)
"""

from __future__ import annotations

import casadi as ca
import numpy as np

from hp_model.domains import Domain, FootPart
from hp_model.dynamics import constrained_accel, constraint_terms
from hp_model.human_prosthesis import HumanProsthesisModel
from hp_model.hybrid import Constraint, ConstraintKind, ContactDomain, HybridModel
from hp_model.tree import frame_pose, rot

SUB_COORDS = ("x_Bp", "z_Bp", "th_Bp", "th_pk", "th_pa")


#: the subsystem's domain of each way its foot touches the ground: flat (the paper's ps), on
#: its heel or its toe (the multi-contact graph's)
_CONTACT_DOMAINS = {FootPart.FLAT: Domain.PS.value, FootPart.HEEL: "p_heel",
                    FootPart.TOE: "p_toe"}


class ProsthesisSubsystem(HybridModel):
    """The prosthesis alone, built from a :class:`HumanProsthesisModel`'s tree: its foot flat
    (the paper's ps) and, when the full model walks the multi-contact graph, on its heel or
    toe (the parts its graph's domains touch the ground with)."""

    def __init__(self, full: HumanProsthesisModel) -> None:
        tree = full.tree.subtree("p_top", base_coords=SUB_COORDS[:3])
        p = full.device.prosthesis
        foot = Constraint("p_foot", ConstraintKind.FRAME, "p_sole")
        parts = {c.part for d in full.graph.domains
                 if (c := d.prosthesis_contact) is not None} - {FootPart.FLAT}
        points = tuple(ContactDomain(_CONTACT_DOMAINS[part], (Constraint(
            _CONTACT_DOMAINS[part], ConstraintKind.POINT, f"p_{part.value}"),))
            for part in (FootPart.HEEL, FootPart.TOE) if part in parts)
        super().__init__(
            tree, ("th_pk", "th_pa"), (p.knee.gear_ratio.value, p.ankle.gear_ratio.value),
            (ContactDomain(Domain.PS, (foot,)), *points), name="prosthesis5",
        )
        self.full = full
        self.torque_limits = full.torque_limits[4:]
        q, qd, u = self.q, self.qd, self.u
        Fs = ca.SX.sym("F_s", 3)

        # body Jacobian of the base frame: (R(th)^T dp/dq ; dth/dq)
        base = frame_pose(tree, q, "socket", self.poses)
        Jw = ca.jacobian(base, q)
        Js = ca.vertcat(rot(base[2]).T @ Jw[0:2, :], Jw[2, :])
        forcing = ca.DM(self.B) @ u + Js.T @ Fs
        J, Jdqd = constraint_terms(self.h[Domain.PS], q, qd)
        qdd, lam = constrained_accel(self.D, self.H, forcing, J, Jdqd)
        self.functions["sub_dyn"] = ca.Function(
            "sub_dyn", [q, qd, u, Fs], [qdd, lam], ["q", "qd", "u", "F_s"], ["qdd", "lam"])
        for point in points:
            J, Jdqd = constraint_terms(self.h[point.name], q, qd)
            qdd_pt, lam_pt = constrained_accel(self.D, self.H, forcing, J, Jdqd)
            name = f"sub_dyn_{point.name}"
            self.functions[name] = ca.Function(name, [q, qd, u, Fs], [qdd_pt, lam_pt],
                                               ["q", "qd", "u", "F_s"], ["qdd", "lam"])
        self.functions["jac_socket"] = ca.Function("jac_socket", [q], [Js], ["q"], ["J_s"])

        # embedding of x_p with the sole flat at the origin
        xp = ca.SX.sym("x_p", 4)
        qj, qjd = xp[0:2], xp[2:4]
        q0 = ca.vertcat(0, 0, 0, qj)
        sole0 = frame_pose(tree, q0, "p_sole")  # base at the origin, zero pitch
        th_b = -sole0[2]
        pos_b = -rot(th_b) @ sole0[0:2]
        q_emb = ca.vertcat(pos_b, th_b, qj)
        qd_emb = ca.jacobian(q_emb, qj) @ qjd
        self.functions["embed"] = ca.Function("embed", [xp], [q_emb, qd_emb], ["x_p"], ["q", "qd"])

        acc = ca.substitute(qdd[3:5], ca.vertcat(q, qd), ca.vertcat(q_emb, qd_emb))
        drift = ca.substitute(acc, ca.vertcat(u, Fs), ca.DM.zeros(5))
        g_m = ca.jacobian(acc, u)  # exact: the dynamics are affine in u and F_s
        g_s = ca.jacobian(acc, Fs)
        f_p = ca.vertcat(qjd, drift)
        z2 = ca.SX.zeros(2, 2)
        z3 = ca.SX.zeros(2, 3)
        self.functions["reduced"] = ca.Function(
            "reduced", [xp], [f_p, ca.vertcat(z2, g_m), ca.vertcat(z3, g_s)],
            ["x_p"], ["f_p", "g_m", "g_s"])
        self.x_p = xp

    @staticmethod
    def contact_domain(part: FootPart) -> str:
        """The subsystem's domain with its foot on the ground so (``ps`` flat, ``p_heel``,
        ``p_toe``); its dynamics ``sub_dyn`` (flat) or ``sub_dyn_<domain>``."""
        return _CONTACT_DOMAINS[FootPart(part)]

    def from_full(
        self, q: np.ndarray, qd: np.ndarray, qdd: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Subsystem (q, qd, qdd) of a full-model motion: the socket frame's world pose and
        its derivatives, then knee and ankle."""
        full = self.full
        fs = full.numeric()
        i = full.frame_index("socket")
        pose, vel = fs["frames"](q, qd)
        base, based = pose[:, i].copy(), vel[:, i].copy()
        basedd = fs["frame_acc"](q, qd, qdd)[0][:, i].copy()
        j = [full.coord_names.index(c) for c in ("th_pk", "th_pa")]
        return np.r_[base, q[j]], np.r_[based, qd[j]], np.r_[basedd, qdd[j]]
