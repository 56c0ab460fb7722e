"""Put the walker on its stance foot: the one placement of the model, symbolic (CasADi SX),
compiled for Python and generated into the FMU's C.

:func:`place` (the placement): given a configuration q and velocities qd of a domain d,

- q with the floating base (x_B, z_B, th_B) moved so that d's stance frame (its first frame
  constraint: the stance sole) is flat (pitch 0) on the ground at (x, 0); the joint angles
  are kept;
- qd with the base velocity solving J_foot qd = 0 (the stance foot at rest; J_foot the
  stance frame's pose Jacobian at the placed q); the joint rates are kept.

The constrained dynamics hold only the constraint's acceleration: a foot velocity left in qd
would drift the stance foot off the ground for the whole step.

The walker's states built on it (:class:`hp_model.outputs.VirtualConstraints` puts the joints
on the outputs; ``theta`` the packed gait of the domain):

    start_<d>(q0, qd0, theta, offset)   the start of a walk from (q0, qd0) with the
        prosthesis (knee, ankle) moved by ``offset`` (rad): the stance knee and ankle of the
        result set the phase and its rate, the other human y2 joints go on their outputs
        at that phase (``VirtualConstraints.on_outputs``), placed with the stance foot at the
        x where q0 has it.  ``offset`` = 0 keeps (q0, qd0) (a start on its stance foot, e.g.
        the gait's optimized one).  What the closed-loop scenarios and the FMU's
        offset_knee/offset_ankle parameters start from.
    zero_dynamics_<d>(tau, theta)       the nominal posture at phase tau moving at the gait's
        nominal rate v_hip / (p_max - p_min) (y1 = y2 = dy2 = 0), placed at x = 0: where
        playback starts.

``place_<d>(q, qd, x)`` is one of the model's functions (``model.numeric()``, numeric
:meth:`hp_model.hybrid.HybridModel.stance_state`); ``start_<d>`` and ``zero_dynamics_<d>`` are
the closed loop's (:meth:`hp_model.closed_loop.ClosedLoop.start_state`,
:meth:`~hp_model.closed_loop.ClosedLoop.zero_dynamics_state`).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import casadi as ca

if TYPE_CHECKING:
    from hp_model.hybrid import HybridModel
    from hp_model.outputs import VirtualConstraints


def place(model: HybridModel, domain: str, q: ca.SX, qd: ca.SX, x: ca.SX | float = 0.0
          ) -> tuple[ca.SX, ca.SX]:
    """(q, qd) placed on the stance foot of ``domain`` at (x, 0) (module docstring)."""
    frame = model.stance_frame(domain)
    nq = model.nq

    def with_base(base: list) -> ca.SX:
        return ca.vertcat(*base, *(q[i] for i in range(3, nq)))

    # the sole's pitch is th_B plus joint angles (planar tree): flat -> th_B = -pitch at 0
    th_B = -model.frame_expr(frame, with_base([0, 0, 0]))[2]
    pos = model.frame_expr(frame, with_base([0, 0, th_B]))[0:2]
    q_placed = with_base([x - pos[0], -pos[1], th_B])
    qs = ca.SX.sym("q", nq)
    Jf = ca.Function("Jf", [qs], [ca.jacobian(model.frame_expr(frame, qs), qs)])(q_placed)
    qd_rest = ca.vertcat(*(qd[i] for i in range(3, nq)))
    qd_base = -ca.solve(Jf[:, 0:3], Jf[:, 3:] @ qd_rest)
    return q_placed, ca.vertcat(qd_base, qd_rest)


def place_function(model: HybridModel, domain: str) -> ca.Function:
    """``place_<d>(q, qd, x) -> (q, qd)``."""
    q, qd, x = ca.SX.sym("q", model.nq), ca.SX.sym("qd", model.nq), ca.SX.sym("x")
    qp, qdp = place(model, domain, q, qd, x)
    return ca.Function(f"place_{domain}", [q, qd, x], [qp, qdp], ["q", "qd", "x"],
                       ["q_placed", "qd_placed"])


def walker_functions(vc: VirtualConstraints) -> list[ca.Function]:
    """``start_<d>`` and ``zero_dynamics_<d>`` of the domain of ``vc`` (module docstring)."""
    model, d, r = vc.model, vc.domain, vc.roles
    nq = model.nq
    theta = ca.SX.sym("theta", vc.n_params)
    q0, qd0, offset = ca.SX.sym("q0", nq), ca.SX.sym("qd0", nq), ca.SX.sym("offset", 2)
    moved = [q0[i] for i in range(nq)]
    for k, i in enumerate(r.prosthesis):
        moved[i] = moved[i] + offset[k]
    q, qd, _ = vc.on_outputs(ca.vertcat(*moved), qd0, theta)
    x0 = model.frame_expr(r.stance_frame, q0)[0]  # the stance foot stays where q0 has it
    q, qd = place(model, d, q, qd, x0)
    kept = ca.logic_and(offset[0] == 0, offset[1] == 0)
    start = ca.Function(f"start_{d}", [q0, qd0, theta, offset],
                        [ca.if_else(kept, q0, q), ca.if_else(kept, qd0, qd)],
                        ["q0", "qd0", "theta", "offset"], ["q", "qd"])
    tau = ca.SX.sym("tau")
    q, qd = vc.posture_exprs(tau, vc.nominal_rate(theta), theta)
    q, qd = place(model, d, q, qd)
    zero = ca.Function(f"zero_dynamics_{d}", [tau, theta], [q, qd], ["tau", "theta"],
                       ["q", "qd"])
    return [start, zero]
