"""Closed-loop vector fields and their RK4 steps, per domain (symbolic, compiled once).

The plant is the domain's constrained dynamics (``dyn_<d>``); the torques come from the
feedback linearization of the outputs (:mod:`hp_model.outputs`), evaluated continuously
(at every RK4 stage):

    mode "full":  all 6 torques from ``fl_<d>`` (gait verification, playback)
    mode "human": the 4 human torques from ``hfl_<d>`` given the prosthesis motor torque u_p,
                  held constant over the step (zero-order hold of a prosthesis controller)

Functions, with x = (q, qd) (24,):

    xdot_<mode>_<d>(x, theta, gains[, u_p])        -> xdot, u (6), lam (6)
    rk4_<mode>_<d>(x, theta, gains[, u_p], h)      -> x_next, height (swing sole z at x_next)
    rk4k_<mode>_<d>(x, theta, gains[, u_p], h, k1) -> the same, given k1 = xdot(x, ...)

``rk4`` is one step of Ralston's fourth-order Runge-Kutta method (:func:`rk4_step`: four
evaluations of the vector field, the classical method's order with a smaller error), built
in MX around one call of ``xdot`` so the generated C contains the vector field once.
``rk4k`` is the same step
with its first stage given: a caller that has already evaluated xdot at x under the same
inputs (the period's friction-cone check) saves one evaluation, with the same arithmetic
(``rk4k(x, .., h, xdot(x, ..)) == rk4(x, .., h)`` bit for bit: the same graph, the same
generated function for the stage).  The in-process simulator and the FMU's C code call these
same functions, so the two integrate with identical arithmetic.

The delayed human (:mod:`hp_model.simulator`) needs the same laws with the feedback term
given instead of computed from the state (compiled separately, on first use, by
:meth:`ClosedLoop.delayed`):

    mode "dfull":  xdot_dfull_<d>(x, theta, v (6))          all 6 torques from ``flv_<d>``
    mode "dhuman": xdot_dhuman_<d>(x, theta, v_h (4), u_p)  human torques from ``hflv_<d>``
    and rk4_dfull_<d>(x, theta, v, h), rk4_dhuman_<d>(x, theta, v_h, u_p, h)

With them, compiled together, the walker's phase and outputs and its placed states
(:mod:`hp_model.outputs`, :mod:`hp_model.placement`):

    phase_<d>(q, theta) -> tau,  outputs_<d>(q, qd, theta) -> y1, y2, dy2, tau
    start_<d>(q0, qd0, theta, offset) -> q, qd,  zero_dynamics_<d>(tau, theta) -> q, qd
"""

from __future__ import annotations

from collections.abc import Sequence

import casadi as ca
import numpy as np

from hp_model.choices import Choice
from hp_model.compiled import FunctionSet
from hp_model.contact_outputs import ContactConstraints, virtual_constraints
from hp_model.domains import Domain
from hp_model.human_prosthesis import HumanProsthesisModel
from hp_model.outputs import VirtualConstraints
from hp_model.placement import walker_functions

#: a domain's virtual constraints: the paper's or the multi-contact graph's
DomainConstraints = VirtualConstraints | ContactConstraints


class ClosedLoopMode(Choice):
    """Where the prosthesis torques come from (module docstring); the value names the
    functions (``rk4_<mode>_<d>``, delayed ``rk4_d<mode>_<d>``)."""

    FULL = "full"  # feedback linearization of all 6 torques
    HUMAN = "human"  # the human's 4; the prosthesis's given (u_p)


_S5 = float(np.sqrt(5.0))
#: Ralston's fourth-order Runge-Kutta method (A. Ralston, "Runge-Kutta methods with minimum
#: error bounds", Math. Comp. 16, 1962): the stage coefficients a_ij (i > j) and the weights
#: b_i, nodes (0, 0.4, 0.4557, 1).  Four evaluations per step like the classical RK4, whose
#: order it has, with the smallest truncation-error bound of the four-stage fourth-order
#: methods: on the demo walk at one step per 1 ms period its state error at the impacts is
#: about a quarter of the classical method's (benchmarks/bench_accuracy.py).
RK4_A = ((),
         (0.4,),
         ((-2889 + 1428 * _S5) / 1024, (3785 - 1620 * _S5) / 1024),
         ((-3365 + 2094 * _S5) / 6040, (-975 - 3046 * _S5) / 2552,
          (467040 + 203968 * _S5) / 240845))
RK4_B = ((263 + 24 * _S5) / 1812, (125 - 1000 * _S5) / 3828,
         (3426304 + 1661952 * _S5) / 5924787, (30 - 4 * _S5) / 123)


def _weighted(coef, ks):
    """sum_i coef_i k_i, left to right."""
    acc = coef[0] * ks[0]
    for c, k in zip(coef[1:], ks[1:], strict=True):
        acc = acc + c * k
    return acc


def rk4_step(fx, x, h, k1):
    """One step of the method (:data:`RK4_A`, :data:`RK4_B`) of length h from x with the first
    stage k1 = fx(x) given (symbolic or numeric; the arithmetic of the generated ``rk4``
    functions)."""
    ks = [k1]
    for a in RK4_A[1:]:
        ks.append(fx(x + h * _weighted(a, ks)))
    return x + h * _weighted(RK4_B, ks)


def _rk4_pair(fx, name: str, nx: int, inputs: list, names: list[str], height: ca.Function
              ) -> list[ca.Function]:
    """``rk4<name>`` and ``rk4k<name>`` (first stage given) in MX around calls of ``fx``."""
    X, H, K1 = ca.MX.sym("x", nx), ca.MX.sym("h"), ca.MX.sym("k1", nx)
    Xn = rk4_step(fx, X, H, fx(X))
    Xk = rk4_step(fx, X, H, K1)
    return [ca.Function(f"rk4{name}", [X, *inputs, H], [Xn, height(Xn)], ["x", *names, "h"],
                        ["x_next", "height"]),
            ca.Function(f"rk4k{name}", [X, *inputs, H, K1], [Xk, height(Xk)],
                        ["x", *names, "h", "k1"], ["x_next", "height"])]


def _rk4_of(f: ca.Function, name: str, nx: int, extra: list[tuple[str, int]],
            height: ca.Function) -> ca.Function:
    """The step in MX around one call of ``f(x, *extra)`` (the first output is xdot)."""
    E = [ca.MX.sym(n, k) for n, k in extra]

    def fx(xx):
        return f(xx, *E)[0]

    return _rk4_pair(fx, name.removeprefix("rk4"), nx, E, [n for n, _ in extra], height)[0]


def delayed_functions(model: HumanProsthesisModel, vc: VirtualConstraints
                      ) -> list[ca.Function]:
    """xdot and rk4 of modes dfull and dhuman of one domain (module docstring)."""
    d, nq = vc.domain, model.nq
    x = ca.SX.sym("x", 2 * nq)
    q, qd = x[:nq], x[nq:]
    theta = ca.SX.sym("theta", vc.n_params)
    v = ca.SX.sym("v", 6)
    v_h = ca.SX.sym("v_h", 4)
    u_p = ca.SX.sym("u_p", 2)
    dyn = model.function(f"dyn_{d}")
    swing = model.roles[d].swing_frame
    height = ca.Function("h", [x], [model.frame_expr(swing, q)[1]])
    out: list[ca.Function] = []
    for mode, u, extra in (
            (ClosedLoopMode.FULL, vc.functions[f"flv_{d}"](q, qd, theta, v), [("v", v)]),
            (ClosedLoopMode.HUMAN, vc.functions[f"hflv_{d}"](q, qd, theta, v_h, u_p),
             [("v_h", v_h), ("u_p", u_p)])):
        qdd, lam = dyn(q, qd, u)
        f = ca.Function(f"xdot_d{mode}_{d}", [x, theta, *(s for _, s in extra)],
                        [ca.vertcat(qd, qdd), u, lam],
                        ["x", "theta", *(n for n, _ in extra)], ["xdot", "u", "lam"],
                        {"cse": True})
        dims = [("theta", vc.n_params)] + [(n, s.numel()) for n, s in extra]
        out += [f, _rk4_of(f, f"rk4_d{mode}_{d}", 2 * nq, dims, height)]
    return out


def guard_height(model: HumanProsthesisModel, domain: str, x: ca.SX) -> ca.Function:
    """x -> the height (m) of the frame whose touchdown ends ``domain`` (its guard); a
    domain ended by a lift-off (no touchdown: :meth:`DomainGraph.touchdown_frame`) has none,
    its height is 1 (the simulator ends it at tau = 1)."""
    frame = model.domains[domain].swing_frame
    z = ca.SX(1.0) if frame is None else model.frame_expr(frame, x[:model.nq])[1]
    return ca.Function("h", [x], [z])


def closed_loop_functions(model: HumanProsthesisModel, vc: DomainConstraints
                          ) -> list[ca.Function]:
    """The xdot and rk4 functions of one domain, both modes."""
    d, nq = vc.domain, model.nq
    x = ca.SX.sym("x", 2 * nq)
    q, qd = x[:nq], x[nq:]
    theta = ca.SX.sym("theta", vc.n_params)
    gains = ca.SX.sym("gains", 3)
    u_p = ca.SX.sym("u_p", 2)
    dyn = model.function(f"dyn_{d}")
    fl, hfl = vc.functions[f"fl_{d}"], vc.functions[f"hfl_{d}"]
    height = guard_height(model, d, x)

    out: list[ca.Function] = []
    u_full = fl(q, qd, theta, gains)[0]
    u_human = hfl(q, qd, theta, gains, u_p)
    for mode, u, extra in ((ClosedLoopMode.FULL, u_full, []),
                           (ClosedLoopMode.HUMAN, u_human, [u_p])):
        qdd, lam = dyn(q, qd, u)
        names = ["x", "theta", "gains"] + (["u_p"] if extra else [])
        f = ca.Function(f"xdot_{mode}_{d}", [x, theta, gains, *extra],
                        [ca.vertcat(qd, qdd), u, lam], names, ["xdot", "u", "lam"],
                        {"cse": True})
        # the step in MX: one xdot in the generated code, called four (rk4k: three) times
        TH = ca.MX.sym("theta", vc.n_params)
        G = ca.MX.sym("gains", 3)
        UP = [ca.MX.sym("u_p", 2)] if extra else []

        def fx(xx, f=f, TH=TH, G=G, UP=UP):
            return f(xx, TH, G, *UP)[0]

        out += [f, *_rk4_pair(fx, f"_{mode}_{d}", 2 * nq, [TH, G, *UP], names[1:], height)]
    return out


class ClosedLoop:
    """The compiled closed-loop functions of every domain of the model's graph for one
    Bezier degree (the paper's graph: with the walker's placed states, ``start_<d>`` and
    ``zero_dynamics_<d>``)."""

    def __init__(self, model: HumanProsthesisModel, degree: int) -> None:
        self.model, self.degree = model, degree
        self.vcs: dict[Domain, DomainConstraints] = {
            d: virtual_constraints(model, d, degree) for d in model.graph.domains}
        fns: list[ca.Function] = []
        for d, vc in self.vcs.items():
            fns += closed_loop_functions(model, vc)
            fns += [vc.functions[f"outputs_{d}"], vc.functions[f"phase_{d}"]]
            if isinstance(vc, VirtualConstraints):
                fns += walker_functions(vc)
        self.functions = {f.name(): f for f in fns}
        self._numeric: FunctionSet | None = None
        self._delayed: FunctionSet | None = None

    def paper_constraints(self, domain: Domain) -> VirtualConstraints:
        """The paper's virtual constraints of ``domain`` (ValueError on another graph: what
        reads the paper's hip progress and roles runs on the paper's graph only)."""
        vc = self.vcs[domain]
        if not isinstance(vc, VirtualConstraints):
            raise ValueError(f"the paper's outputs of {domain} are not on the "
                             f"{self.model.graph} graph")
        return vc

    def numeric(self) -> FunctionSet:
        if self._numeric is None:
            self._numeric = FunctionSet(list(self.functions.values()),
                                        f"{self.model.name}_cl_m{self.degree}")
        return self._numeric

    def start_state(self, domain: str, q0: np.ndarray, qd0: np.ndarray, theta: np.ndarray,
                    offset: Sequence[float] = (0.0, 0.0)) -> tuple[np.ndarray, np.ndarray]:
        """Copies of ``start_<d>``: the start of a walk from (q0, qd0) with the prosthesis
        (knee, ankle) moved by ``offset`` (rad) (:mod:`hp_model.placement`)."""
        q, qd = self.numeric()[f"start_{domain}"](q0, qd0, theta, np.asarray(offset, float))
        return q.copy(), qd.copy()

    def zero_dynamics_state(self, domain: str, tau: float, theta: np.ndarray
                            ) -> tuple[np.ndarray, np.ndarray]:
        """Copies of ``zero_dynamics_<d>``: the gait's posture at phase ``tau`` moving at its
        nominal rate, placed at x = 0 (:mod:`hp_model.placement`)."""
        q, qd = self.numeric()[f"zero_dynamics_{domain}"](tau, theta)
        return q.copy(), qd.copy()

    def delayed(self) -> FunctionSet:
        """The compiled functions of the delayed human (module docstring), built on first
        use (most runs never need them)."""
        if self._delayed is None:
            fns: list[ca.Function] = []
            for vc in self.vcs.values():
                if not isinstance(vc, VirtualConstraints):
                    raise ValueError(f"the delayed human runs the paper's graph only, not "
                                     f"{self.model.graph}")
                fns += delayed_functions(self.model, vc)
            self._delayed = FunctionSet(fns, f"{self.model.name}_cld_m{self.degree}")
        return self._delayed
