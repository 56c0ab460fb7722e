"""Export a :class:`~hp_model.tree.PlanarTree` as URDF.

Planar joints become a prismatic-x, prismatic-z, revolute-y chain through massless links;
revolute joints turn about +y, so the URDF has the same coordinates with the same signs
(every joint named after its coordinate).  Used as an independent oracle (Pinocchio and
MuJoCo load it) and to view the model in any URDF tool.

For MuJoCo, which refuses moving bodies without mass: a ``<mujoco><compiler>`` extension
element (ignored by other URDF readers) bounds every body's mass and inertia from below
(``BOUND_MASS`` kg, ``BOUND_INERTIA`` kg m^2 on the massless links of the planar chains:
10^-11 of the walker's mass, below any tolerance the comparisons use), and every inertia
is written with ixx = izz = iyy (a valid 3-D inertia; only iyy acts in the plane).
"""

from __future__ import annotations

from xml.sax.saxutils import quoteattr

from hp_model.tree import JointKind, PlanarTree

_LIMIT = '<limit effort="1e6" velocity="1e6" lower="-1e3" upper="1e3"/>'
BOUND_MASS = 1e-9
BOUND_INERTIA = 1e-12


def _origin(xyz: tuple[float, float, float], pitch: float = 0.0) -> str:
    return f'<origin xyz="{xyz[0]!r} {xyz[1]!r} {xyz[2]!r}" rpy="0 {pitch!r} 0"/>'


def _joint(name: str, kind: str, parent: str, child: str, axis: str, origin: str) -> str:
    return (
        f"  <joint name={quoteattr(name)} type={quoteattr(kind)}>\n"
        f"    <parent link={quoteattr(parent)}/><child link={quoteattr(child)}/>\n"
        f"    {origin}<axis xyz={quoteattr(axis)}/>{_LIMIT}\n  </joint>\n"
    )


def to_urdf(tree: PlanarTree, robot_name: str = "hpcosim") -> str:
    """URDF text of the tree (world link ``world``; gravity is the importer's, -z)."""
    out = [f'<?xml version="1.0"?>\n<robot name={quoteattr(robot_name)}>\n'
           f'  <mujoco><compiler boundmass="{BOUND_MASS!r}" boundinertia="{BOUND_INERTIA!r}" '
           'balanceinertia="false" fusestatic="false" discardvisual="false"/></mujoco>\n'
           '  <link name="world"/>\n']
    for b in tree.bodies:
        parent = "world" if b.parent is None else b.parent
        px, pz = b.placement
        if b.joint == JointKind.PLANAR:
            cx, cz, cth = b.coords
            out.append(f'  <link name="{b.name}__px"/>\n  <link name="{b.name}__pz"/>\n')
            out.append(_joint(cx, "prismatic", parent, f"{b.name}__px", "1 0 0",
                              _origin((px, 0.0, pz), b.placement_angle)))
            out.append(_joint(cz, "prismatic", f"{b.name}__px", f"{b.name}__pz", "0 0 1",
                              _origin((0.0, 0.0, 0.0))))
            out.append(_joint(cth, "revolute", f"{b.name}__pz", b.name, "0 1 0",
                              _origin((0.0, 0.0, 0.0))))
        else:
            out.append(_joint(b.coords[0], "revolute", parent, b.name, "0 1 0",
                              _origin((px, 0.0, pz), b.placement_angle)))
        inertial = ""
        if b.mass > 0:
            i = b.inertia if b.inertia > 0 else BOUND_INERTIA
            inertial = (
                f"    <inertial>{_origin((b.com[0], 0.0, b.com[1]))}"
                f'<mass value="{b.mass!r}"/>'
                f'<inertia ixx="{i!r}" iyy="{i!r}" izz="{i!r}" ixy="0" ixz="0" iyz="0"/>'
                f"</inertial>\n"
            )
        out.append(f"  <link name={quoteattr(b.name)}>\n{inertial}  </link>\n")
    out.append("</robot>\n")
    return "".join(out)
