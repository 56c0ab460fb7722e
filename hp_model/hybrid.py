"""A planar tree with actuators and holonomic-constraint domains: the hybrid control system
(paper Sec. III) in symbolic form, plus its compiled numeric functions.

Domains hold their constraints as an ordered stack.  A ``frame`` constraint holds a frame's
world pose (x, z, pitch) fixed (flat foot); its wrench is the ground reaction force
(F_x, F_z) at the frame's point and the moment M_y, in world axes.  A ``point`` constraint
holds a frame's position (x, z) (a foot on its heel or toe, free to pitch); its wrench is
(F_x, F_z) at the point.  A ``coords`` constraint
holds joint coordinates at zero (the socket's fixed joint); its wrench is the generalized
force on those coordinates, i.e. the wrench of the parent on the child in the joint frame.

Symbolic functions (CasADi, callable with SX/MX/DM) are named:

    terms_<d>(q, qd)        -> D, H, J_d, Jdot_d qd
    dyn_<d>(q, qd, u)       -> qdd, lam_d                 (KKT solve)
    impact_<d>(q, qd_minus) -> qd_plus, impulse           (impact INTO domain d)
    guard_<d>(q, qd)        -> height, vertical velocity of the swing frame in d
    energy(q, qd)           -> kinetic, potential
    frames(q, qd)           -> poses (3 x nf), velocities (3 x nf) of all named frames
    frame_acc(q, qd, qdd)   -> accelerations (3 x nf) of all named frames
    place_<d>(q, qd, x)     -> q, qd on the stance foot of d at (x, 0) (:mod:`hp_model.placement`)
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import casadi as ca
import numpy as np

from hp_model.choices import Choice
from hp_model.compiled import CompileBackend, FunctionSet
from hp_model.dynamics import (
    constrained_accel,
    constraint_terms,
    energies,
    impact_map,
    mass_matrix_and_bias,
)
from hp_model.placement import place_function
from hp_model.tree import ModelError, PlanarTree, body_poses, frame_pose


class ConstraintKind(Choice):
    """What a :class:`Constraint` holds (module docstring)."""

    FRAME = "frame"  # target: a frame name; h = its world pose (x, z, pitch), 3 rows
    POINT = "point"  # target: a frame name; h = its world position (x, z), 2 rows
    COORDS = "coords"  # target: a tuple of coordinate names; h = those coordinates


@dataclass(frozen=True)
class Constraint:
    """One block of holonomic constraints of a :class:`ConstraintKind` (given as the enum
    or its value) on ``target``."""

    name: str
    kind: ConstraintKind
    target: str | tuple[str, ...]

    def __post_init__(self) -> None:
        object.__setattr__(self, "kind", ConstraintKind(self.kind))

    @property
    def size(self) -> int:
        if self.kind == ConstraintKind.COORDS:
            return len(self.target)
        return 3 if self.kind == ConstraintKind.FRAME else 2


@dataclass(frozen=True)
class ContactDomain:
    """A continuous domain: its constraint stack, the frame whose touchdown is its guard,
    and the domain the guard leads to."""

    name: str
    constraints: tuple[Constraint, ...]
    swing_frame: str | None = None
    next: str | None = None

    @property
    def n_constraints(self) -> int:
        return sum(c.size for c in self.constraints)

    def wrench_slice(self, constraint: str) -> slice:
        """Rows of lam_d holding the named constraint's wrench."""
        o = 0
        for c in self.constraints:
            if c.name == constraint:
                return slice(o, o + c.size)
            o += c.size
        raise ModelError(f"domain '{self.name}' has no constraint '{constraint}'")


class HybridModel:
    """Symbolic and numeric dynamics of an actuated planar tree with domains.

    The model is immutable after construction.  ``numeric()`` compiles (once, cached on
    disk by source hash) and returns the :class:`~hp_model.compiled.FunctionSet` of all
    functions listed in the module docstring.
    """

    def __init__(
        self,
        tree: PlanarTree,
        actuated: Sequence[str],
        gear_ratios: Sequence[float],
        domains: Sequence[ContactDomain],
        name: str,
        backend: CompileBackend | str = CompileBackend.AUTO,
    ) -> None:
        if len(actuated) != len(gear_ratios):
            raise ModelError("one gear ratio per actuated coordinate")
        self.backend = CompileBackend(backend)
        self.tree = tree
        self.name = name
        self.nq = tree.nq
        self.nu = len(actuated)
        self.coord_names = tree.coord_names
        self.actuated = tuple(actuated)
        B = np.zeros((self.nq, self.nu))
        for j, (c, r) in enumerate(zip(actuated, gear_ratios, strict=True)):
            B[tree.coord_index(c), j] = r
        self.B = B
        self.B.setflags(write=False)
        self.domains = {d.name: d for d in domains}
        for d in domains:
            if d.next is not None and d.next not in self.domains:
                raise ModelError(f"domain '{d.name}': next domain '{d.next}' is not defined")
        self.frame_names = tuple(f.name for f in tree.frames)

        q = ca.SX.sym("q", self.nq)
        qd = ca.SX.sym("qd", self.nq)
        u = ca.SX.sym("u", self.nu)
        self.q, self.qd, self.u = q, qd, u
        self.poses = body_poses(tree, q)
        self.D, self.H = mass_matrix_and_bias(tree, q, qd)
        T, V = energies(tree, q, qd)
        Bu = ca.DM(B) @ u

        fns: list[ca.Function] = [
            ca.Function("energy", [q, qd], [T, V], ["q", "qd"], ["T", "V"]),
        ]
        fr = [frame_pose(tree, q, f, self.poses) for f in self.frame_names]
        if fr:
            P = ca.horzcat(*fr)
            Pd = ca.jtimes(P, q, qd)
            fns.append(ca.Function("frames", [q, qd], [P, Pd], ["q", "qd"], ["pose", "vel"]))
            qdd = ca.SX.sym("qdd", self.nq)
            Pdd = ca.jtimes(P, q, qdd) + ca.jtimes(Pd, q, qd)
            fns.append(ca.Function("frame_acc", [q, qd, qdd], [Pdd], ["q", "qd", "qdd"], ["acc"]))

        self.h: dict[str, ca.SX] = {}
        for d in domains:
            h = self.constraint_expr(d.constraints)
            self.h[d.name] = h
            J, Jdqd = constraint_terms(h, q, qd)
            qdd, lam = constrained_accel(self.D, self.H, Bu, J, Jdqd)
            qd_plus, imp = impact_map(self.D, J, qd)
            fns += [
                ca.Function(f"terms_{d.name}", [q, qd], [self.D, self.H, J, Jdqd],
                            ["q", "qd"], ["D", "H", "J", "Jdqd"]),
                ca.Function(f"dyn_{d.name}", [q, qd, u], [qdd, lam],
                            ["q", "qd", "u"], ["qdd", "lam"]),
                ca.Function(f"impact_{d.name}", [q, qd], [qd_plus, imp],
                            ["q", "qd_minus"], ["qd_plus", "impulse"]),
            ]
            if d.swing_frame is not None:
                pz = frame_pose(tree, q, d.swing_frame, self.poses)[1]
                fns.append(ca.Function(f"guard_{d.name}", [q, qd], [pz, ca.jtimes(pz, q, qd)],
                                       ["q", "qd"], ["height", "vz"]))
        self.functions: dict[str, ca.Function] = {
            f.name(): f.expand() if f.is_a("MXFunction") else f for f in fns
        }
        for d in domains:
            if any(c.kind == ConstraintKind.FRAME for c in d.constraints):
                self.functions[f"place_{d.name}"] = place_function(self, d.name)
        self._numeric: dict[CompileBackend, FunctionSet] = {}

    # -- symbolic helpers --------------------------------------------------------------------
    def constraint_expr(self, constraints: Sequence[Constraint], q: ca.SX | None = None) -> ca.SX:
        """h(q) of a constraint stack (SX in ``q``, default the model's own symbol)."""
        if q is None:
            q, poses = self.q, self.poses
        else:
            poses = body_poses(self.tree, q)
        rows = []
        for c in constraints:
            if c.kind in (ConstraintKind.FRAME, ConstraintKind.POINT):
                assert isinstance(c.target, str)  # a frame constraint names one frame
                pose = frame_pose(self.tree, q, c.target, poses)
                rows.append(pose if c.kind == ConstraintKind.FRAME else pose[:2])
            else:
                rows.append(ca.vertcat(*[q[self.tree.coord_index(n)] for n in c.target]))
        return ca.vertcat(*rows)

    def frame_expr(self, frame: str, q: ca.SX | None = None) -> ca.SX:
        """World pose (x, z, pitch) of a frame as SX."""
        if q is None:
            return frame_pose(self.tree, self.q, frame, self.poses)
        return frame_pose(self.tree, q, frame)

    def function(self, name: str) -> ca.Function:
        """A symbolic function by name (see the module docstring)."""
        try:
            return self.functions[name]
        except KeyError:
            have = sorted(self.functions)
            raise KeyError(f"{self.name}: no function '{name}'; have {have}") from None

    # -- numeric ------------------------------------------------------------------------------
    def numeric(self, backend: CompileBackend | str | None = None) -> FunctionSet:
        """All functions compiled to C (or interpreted) and bound to reusable buffers;
        ``backend`` defaults to the model's (``AUTO``; ``SX`` for a model built for a
        few calls, e.g. a sweep's perturbed plant, whose compilation would cost more than
        interpreting)."""
        backend = CompileBackend(backend or self.backend)
        if backend not in self._numeric:
            fs = FunctionSet(list(self.functions.values()), self.name, backend)
            self._numeric[backend] = fs
            self._numeric[fs.backend] = fs
        return self._numeric[backend]

    def frame_index(self, name: str) -> int:
        return self.frame_names.index(name)

    def stance_frame(self, domain: str) -> str:
        """The frame the domain holds flat on the ground (its first frame constraint)."""
        return str(next(c.target for c in self.domains[domain].constraints
                        if c.kind == ConstraintKind.FRAME))

    def place_stance_foot(self, q: np.ndarray, domain: str, x: float = 0.0) -> np.ndarray:
        """A copy of ``q`` with the floating base moved so that the domain's stance frame
        (its first ``frame`` constraint) is flat (pitch 0) on the ground at (x, 0); joint
        angles are kept (:func:`hp_model.placement.place`)."""
        return self.stance_state(q, np.zeros(self.nq), domain, x)[0]

    def stance_state(self, q: np.ndarray, qd: np.ndarray, domain: str, x: float = 0.0
                     ) -> tuple[np.ndarray, np.ndarray]:
        """Copies of (q, qd) placed on the domain's stance foot at (x, 0), the base velocity
        solving J_foot qd = 0 (:func:`hp_model.placement.place`)."""
        qp, qdp = self.numeric()[f"place_{domain}"](q, qd, x)
        return qp.copy(), qdp.copy()
