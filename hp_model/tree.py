"""Generic planar kinematic trees (sagittal plane) and their symbolic kinematics.

Conventions (all SI):

- World frame: x forward, z up, y = z x x pointing to the walker's left.
- Every rotation is a pitch about +y.  A rotation by ``th`` maps body coordinates (x, z) to
  parent coordinates with ``R(th) = [[cos th, sin th], [-sin th, cos th]]``; a positive angle
  tilts a body's +z axis towards +x.  This is the 3-D pitch convention, so a URDF with joint
  axis (0, 1, 0) (see :mod:`hp_model.urdf`) describes the same model with the same signs.
- A ``revolute`` joint has one coordinate (its angle).  A ``planar`` joint has three,
  ``(x, z, th)``: a translation along the parent's joint-frame axes followed by a rotation.
  The root body's joint is always ``planar`` (the floating base) with the world as parent.
- Coordinates are numbered in body order; a body's parent must come before it.

The tree is an immutable description.  :func:`frame_pose` and friends build CasADi SX
expressions from it; :mod:`hp_model.dynamics` turns those into D, H and the rest.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import casadi as ca

from hp_model.choices import Choice


class ModelError(ValueError):
    """A kinematic tree or model built from inconsistent parts."""


class JointKind(Choice):
    """How a :class:`Body` moves relative to its parent."""

    REVOLUTE = "revolute"  # one angle
    PLANAR = "planar"  # x, z, th (the floating base, the socket)

    @property
    def dof(self) -> int:
        """Number of joint coordinates."""
        return 1 if self is JointKind.REVOLUTE else 3


@dataclass(frozen=True)
class Body:
    """A rigid body and the joint that connects it to its parent.

    Attributes:
        name: unique body name.
        parent: parent body name, or ``None`` for the root (floating base).
        joint: a :class:`JointKind` (or its value).
        coords: names of the joint coordinates (1 for revolute, 3 for planar: x, z, th).
        placement: joint origin in the parent body frame, metres (x, z).
        placement_angle: fixed pitch of the joint frame relative to the parent, rad.
        mass: kg (>= 0; massless bodies are allowed).
        com: centre of mass in the body frame, metres (x, z).
        inertia: moment of inertia about the COM, about y, kg m^2.
        armature: a drive's reflected rotor inertia at a revolute joint, kg m^2 (J_rotor
            N^2): added to the mass matrix's diagonal at the joint's coordinate, as
            Pinocchio's ``model.armature`` (the rotor's own gyroscopic and carrier terms
            neglected).
    """

    name: str
    parent: str | None
    joint: JointKind
    coords: tuple[str, ...]
    placement: tuple[float, float] = (0.0, 0.0)
    placement_angle: float = 0.0
    mass: float = 0.0
    com: tuple[float, float] = (0.0, 0.0)
    inertia: float = 0.0
    armature: float = 0.0

    def __post_init__(self) -> None:
        try:
            object.__setattr__(self, "joint", JointKind(self.joint))
        except ValueError as e:
            raise ModelError(f"body '{self.name}': {e}") from None
        if not self.armature >= 0:
            raise ModelError(f"body '{self.name}': armature {self.armature} must be >= 0")
        if self.armature > 0 and self.joint != JointKind.REVOLUTE:
            raise ModelError(f"body '{self.name}': an armature needs a revolute joint, not "
                             f"{self.joint}")


@dataclass(frozen=True)
class Frame:
    """A named point on a body, with the body's orientation (metres, body frame)."""

    name: str
    body: str
    point: tuple[float, float] = (0.0, 0.0)


#: m/s^2, the model's gravity (a tree's default)
GRAVITY = 9.81


@dataclass(frozen=True)
class PlanarTree:
    """An immutable planar kinematic tree with named frames.

    Build it once; every symbolic or numeric quantity is derived from it.
    """

    bodies: tuple[Body, ...]
    frames: tuple[Frame, ...] = ()
    gravity: float = GRAVITY
    _index: dict[str, int] = field(init=False, repr=False, compare=False)
    _coord_offset: tuple[int, ...] = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        index: dict[str, int] = {}
        offsets: list[int] = []
        n = 0
        for i, b in enumerate(self.bodies):
            if b.name in index:
                raise ModelError(f"duplicate body name '{b.name}'")
            if len(b.coords) != b.joint.dof:
                raise ModelError(
                    f"body '{b.name}': a {b.joint} joint has {b.joint.dof} coordinates, "
                    f"got {len(b.coords)}"
                )
            if i == 0:
                if b.parent is not None or b.joint != JointKind.PLANAR:
                    raise ModelError("the first body must be the root: parent None, planar joint")
            elif b.parent not in index:
                raise ModelError(f"body '{b.name}': parent '{b.parent}' must be defined before it")
            if b.mass < 0 or b.inertia < 0:
                raise ModelError(f"body '{b.name}': mass and inertia must be >= 0")
            index[b.name] = i
            offsets.append(n)
            n += len(b.coords)
        names = [c for b in self.bodies for c in b.coords]
        if len(set(names)) != len(names):
            raise ModelError("coordinate names must be unique")
        fnames = [f.name for f in self.frames]
        if len(set(fnames)) != len(fnames):
            raise ModelError("frame names must be unique")
        for f in self.frames:
            if f.body not in index:
                raise ModelError(f"frame '{f.name}': unknown body '{f.body}'")
        object.__setattr__(self, "_index", index)
        object.__setattr__(self, "_coord_offset", tuple(offsets))

    # -- structure ---------------------------------------------------------------------------
    @property
    def nq(self) -> int:
        return sum(len(b.coords) for b in self.bodies)

    @property
    def coord_names(self) -> tuple[str, ...]:
        return tuple(c for b in self.bodies for c in b.coords)

    @property
    def armature(self) -> dict[str, float]:
        """Coordinate -> its drive's reflected inertia (kg m^2), the joints that have one."""
        return {b.coords[0]: b.armature for b in self.bodies if b.armature > 0}

    @property
    def total_mass(self) -> float:
        return sum(b.mass for b in self.bodies)

    def body(self, name: str) -> Body:
        try:
            return self.bodies[self._index[name]]
        except KeyError:
            raise ModelError(f"unknown body '{name}'") from None

    def frame(self, name: str) -> Frame:
        for f in self.frames:
            if f.name == name:
                return f
        raise ModelError(f"unknown frame '{name}'")

    def coord_index(self, name: str) -> int:
        try:
            return self.coord_names.index(name)
        except ValueError:
            raise ModelError(f"unknown coordinate '{name}'") from None

    def chain(self, body: str) -> list[Body]:
        """Bodies from the root to ``body`` inclusive."""
        out = []
        b: Body | None = self.body(body)
        while b is not None:
            out.append(b)
            b = self.body(b.parent) if b.parent is not None else None
        return out[::-1]

    def subtree(self, root: str, base_coords: tuple[str, str, str] | None = None) -> PlanarTree:
        """The subtree rooted at ``root``, re-rooted on a floating planar base.

        The root body's joint becomes the floating base (coordinates ``base_coords``, default
        ``(<root>_x, <root>_z, <root>_th)``) placed at the world origin; every other body,
        parameter and frame on the subtree is kept as is.
        """
        keep: list[Body] = []
        names: set[str] = set()
        for b in self.bodies:
            if b.name == root:
                keep.append(
                    Body(
                        name=b.name,
                        parent=None,
                        joint=JointKind.PLANAR,
                        coords=base_coords or (f"{root}_x", f"{root}_z", f"{root}_th"),
                        mass=b.mass,
                        com=b.com,
                        inertia=b.inertia,
                    )
                )
                names.add(b.name)
            elif b.parent in names:
                keep.append(b)
                names.add(b.name)
        if not keep:
            raise ModelError(f"unknown body '{root}'")
        frames = tuple(f for f in self.frames if f.body in names)
        return PlanarTree(bodies=tuple(keep), frames=frames, gravity=self.gravity)


# -- symbolic kinematics ---------------------------------------------------------------------
def rot(th: ca.SX) -> ca.SX:
    """Planar pitch rotation R(th) acting on (x, z) column vectors (body -> parent)."""
    c, s = ca.cos(th), ca.sin(th)
    return ca.vertcat(ca.horzcat(c, s), ca.horzcat(-s, c))


def _joint_transform(b: Body, qj: ca.SX) -> tuple[ca.SX, ca.SX]:
    """Pose of the child body frame in the parent frame: (position (2,), angle)."""
    p0 = ca.SX(ca.DM(b.placement))
    a0 = b.placement_angle
    if b.joint == JointKind.REVOLUTE:
        return p0, a0 + qj[0]
    # planar: translate along the joint frame's axes, then rotate
    return p0 + rot(ca.SX(a0)) @ qj[0:2], a0 + qj[2]


def body_poses(tree: PlanarTree, q: ca.SX) -> list[tuple[ca.SX, ca.SX]]:
    """World pose (origin position (2,), pitch angle) of every body, as SX in ``q``."""
    poses: list[tuple[ca.SX, ca.SX]] = []
    for i, b in enumerate(tree.bodies):
        o = tree._coord_offset[i]
        qj = q[o : o + len(b.coords)]
        p_rel, a_rel = _joint_transform(b, qj)
        if b.parent is None:
            poses.append((p_rel, a_rel))
        else:
            pp, pa = poses[tree._index[b.parent]]
            poses.append((pp + rot(pa) @ p_rel, pa + a_rel))
    return poses


def point_position(
    tree: PlanarTree, q: ca.SX, body: str, point: tuple[float, float] | ca.SX = (0.0, 0.0),
    poses: list[tuple[ca.SX, ca.SX]] | None = None,
) -> ca.SX:
    """World position (x, z) of a point given in a body frame."""
    poses = poses if poses is not None else body_poses(tree, q)
    p, a = poses[tree._index[body]]
    return p + rot(a) @ ca.DM(point) if not isinstance(point, ca.SX) else p + rot(a) @ point


def frame_pose(tree: PlanarTree, q: ca.SX, frame: str,
               poses: list[tuple[ca.SX, ca.SX]] | None = None) -> ca.SX:
    """World pose (x, z, pitch) of a named frame, as a 3-vector SX."""
    f = tree.frame(frame)
    poses = poses if poses is not None else body_poses(tree, q)
    _, a = poses[tree._index[f.body]]
    return ca.vertcat(point_position(tree, q, f.body, f.point, poses), a)
