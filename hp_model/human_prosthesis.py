"""The 12-DOF planar human-prosthesis model (paper Sec. III, Fig. 3; REFERENCE.md Sec. 1b).

Coordinates, exactly as the paper:
    q = (x_B, z_B, th_B, th_lh, th_lk, th_la, th_rh, x_f, z_f, th_f, th_pk, th_pa)

- Base frame at the hip; the head-arms-trunk (HAT) body is the base body.
- Left (human) leg: hip th_lh -> thigh -> knee th_lk -> shank -> ankle th_la -> foot.
- Right: hip th_rh -> human thigh carrying the iWalk and the folded shank and foot (one
  lumped body) -> fixed joint q_f = (x_f, z_f, th_f) at the pin connection (the socket),
  held at zero in every domain -> AMPRO3 top link -> knee th_pk -> shin -> ankle th_pa -> foot.
- Angles are pitches about +y (x forward, z up; see :mod:`hp_model.tree`): hip flexion is
  negative, knee flexion positive, ankle plantarflexion positive.  All zero = upright, feet
  flat.
- Domains (:mod:`hp_model.domains`): the model is built for one :class:`DomainGraph`, the
  paper's (``ps``: prosthesis foot flat + fixed joint, ``pns``: human left foot flat + fixed
  joint; 6 constraints each, wrenches ordered foot F_x, F_z, M_y in world axes, then socket
  F_x, F_z, M_y) or the multi-contact one (adds ``ps_toe``/``pns_toe``: the stance toe as a
  point + fixed joint, 5 constraints; ``ds_h``/``ds_p``: the leading foot's heel and the
  trailing foot's toe as points + fixed joint; 7 constraints, wrenches heel F_x, F_z, toe F_x,
  F_z, socket F_x, F_z, M_y).
- Socket force F_s: the wrench of the human (thigh/iWalk) on the prosthesis top link at the
  pin, in the top link's frame (which equals the thigh's frame since th_f = 0).
- Actuators: th_lh, th_lk, th_la, th_rh (human, ratio 1, u in N m at the joint) and
  th_pk, th_pa (AMPRO3, u = motor torque, joint torque = gear ratio * u).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import asdict, dataclass, fields

import casadi as ca
import numpy as np

from hp_model import anthropometry as anth
from hp_model.compiled import CompileBackend
from hp_model.config import DeviceConfig, SubjectConfig
from hp_model.domains import Domain, DomainGraph, DomainRoles, FootContact, domain_roles
from hp_model.hybrid import Constraint, ConstraintKind, ContactDomain, HybridModel
from hp_model.tree import Body, Frame, JointKind, PlanarTree, frame_pose

COORDS = ("x_B", "z_B", "th_B", "th_lh", "th_lk", "th_la", "th_rh",
          "x_f", "z_f", "th_f", "th_pk", "th_pa")
ACTUATED = ("th_lh", "th_lk", "th_la", "th_rh", "th_pk", "th_pa")
SOCKET_COORDS = ("x_f", "z_f", "th_f")


Part = tuple[float, tuple[float, float], float]


def _lump(parts: Sequence[Part]) -> Part:
    """Combine (mass, com, inertia-about-own-com) parts into one rigid body."""
    m = sum(p[0] for p in parts)
    cx = sum(p[0] * p[1][0] for p in parts) / m
    cz = sum(p[0] * p[1][1] for p in parts) / m
    inertia = sum(p[2] + p[0] * ((p[1][0] - cx) ** 2 + (p[1][1] - cz) ** 2) for p in parts)
    return m, (cx, cz), inertia


@dataclass(frozen=True)
class BodyVariation:
    """A body that differs from the subject's anthropometric estimate: dimensionless factors
    (1 = as the tables give) on the human segments' masses (inertia about the COM scales
    with the mass: same radius of gyration), on the HAT's COM distance from the hip, and on
    the iWalk's mass.  The robustness sweeps give the simulated human such a body while the
    controller keeps the nominal one (``plant.*`` quantities of a sweep spec)."""

    hat_mass: float = 1.0
    thigh_mass: float = 1.0
    shank_mass: float = 1.0
    foot_mass: float = 1.0
    hat_com: float = 1.0
    iwalk_mass: float = 1.0

    def __post_init__(self) -> None:
        for f in fields(self):
            v = getattr(self, f.name)
            if not (np.isfinite(v) and v > 0):
                raise ValueError(f"body variation {f.name} must be finite and > 0, got {v}")

    @property
    def is_nominal(self) -> bool:
        return self == BodyVariation()


NOMINAL_BODY = BodyVariation()


def build_tree(subject: SubjectConfig, device: DeviceConfig,
               body: BodyVariation = NOMINAL_BODY) -> PlanarTree:
    """The kinematic tree with segment parameters from the subject and device configs (and
    a :class:`BodyVariation` of the human segments).

    The right thigh body lumps: the human thigh; the shank folded backward at 90 deg onto
    the iWalk platform (COM behind the knee); the foot at the end of that shank (COM half an
    ankle height past the ankle); the iWalk as a uniform rod from the knee down to the pin.
    """
    L = subject.lengths
    sex, tab, M = subject.sex, subject.radii_of_gyration, subject.body_mass

    def seg(name: str, length: float, k: float) -> tuple[float, float, float]:
        m, c, inertia = anth.segment(name, sex, tab, M, length)
        return m * k, c, inertia * k

    m_hat, c_hat, I_hat = seg("hat", L.trunk, body.hat_mass)
    c_hat *= body.hat_com
    m_th, c_th, I_th = seg("thigh", L.thigh, body.thigh_mass)
    m_sh, c_sh, I_sh = seg("shank", L.shank, body.shank_mass)
    m_ft, _, I_ft = seg("foot", L.foot, body.foot_mass)
    foot_com = (L.foot / 2 - L.heel, -L.ankle_height / 2)

    iw = device.iwalk
    m_iw, l_iw = iw.mass.value * body.iwalk_mass, iw.length.value
    r_thigh = _lump([
        (m_th, (0.0, -c_th), I_th),
        (m_sh, (-c_sh, -L.thigh), I_sh),
        (m_ft, (-(L.shank + L.ankle_height / 2), -L.thigh), I_ft),
        (m_iw, (0.0, -L.thigh - l_iw / 2), m_iw * l_iw**2 / 12),
    ])
    p = device.prosthesis
    pf = p.foot

    def link(cfg) -> dict:
        return dict(mass=cfg.mass.value, com=(0.0, -cfg.com.value), inertia=cfg.inertia.value)

    rev, planar = JointKind.REVOLUTE, JointKind.PLANAR
    bodies = (
        Body("hat", None, planar, ("x_B", "z_B", "th_B"),
             mass=m_hat, com=(0.0, c_hat), inertia=I_hat),
        Body("l_thigh", "hat", rev, ("th_lh",), mass=m_th, com=(0.0, -c_th), inertia=I_th),
        Body("l_shank", "l_thigh", rev, ("th_lk",), placement=(0.0, -L.thigh),
             mass=m_sh, com=(0.0, -c_sh), inertia=I_sh),
        Body("l_foot", "l_shank", rev, ("th_la",), placement=(0.0, -L.shank),
             mass=m_ft, com=foot_com, inertia=I_ft),
        Body("r_thigh", "hat", rev, ("th_rh",),
             mass=r_thigh[0], com=r_thigh[1], inertia=r_thigh[2]),
        Body("p_top", "r_thigh", planar, SOCKET_COORDS, placement=(0.0, -(L.thigh + l_iw)),
             **link(p.top)),
        Body("p_shin", "p_top", rev, ("th_pk",), placement=(0.0, -p.top.length.value),
             **link(p.shin), armature=p.knee.armature),
        Body("p_foot", "p_shin", rev, ("th_pa",), placement=(0.0, -p.shin.length.value),
             mass=pf.mass.value, com=(pf.com_x.value, pf.com_z.value), inertia=pf.inertia.value,
             armature=p.ankle.armature),
    )
    h_l, h_p = L.ankle_height, pf.ankle_height.value
    frames = (
        Frame("hip", "hat"),
        Frame("l_knee", "l_shank"),
        Frame("l_ankle", "l_foot"),
        Frame("l_sole", "l_foot", (0.0, -h_l)),
        Frame("l_heel", "l_foot", (-L.heel, -h_l)),
        Frame("l_toe", "l_foot", (L.foot - L.heel, -h_l)),
        Frame("r_knee", "r_thigh", (0.0, -L.thigh)),
        Frame("socket", "p_top"),
        Frame("p_knee", "p_shin"),
        Frame("p_ankle", "p_foot"),
        Frame("p_sole", "p_foot", (0.0, -h_p)),
        Frame("p_heel", "p_foot", (-pf.heel.value, -h_p)),
        Frame("p_toe", "p_foot", (pf.length.value - pf.heel.value, -h_p)),
    )
    tree = PlanarTree(bodies=bodies, frames=frames)
    assert tree.coord_names == COORDS
    return tree


SOCKET = Constraint("socket", ConstraintKind.COORDS, SOCKET_COORDS)


def contact_constraint(contact: FootContact) -> Constraint:
    """A foot's contact as a constraint: its sole flat, or its heel or toe held in place."""
    kind = ConstraintKind.FRAME if contact.is_flat else ConstraintKind.POINT
    return Constraint(contact.name, kind, contact.frame)


def domain_defs(graph: DomainGraph) -> tuple[ContactDomain, ...]:
    """Each domain's constraint stack in ``graph``: its feet's contacts, then the socket's
    fixed joint; its guard the touchdown of the next domain's new contact."""
    return tuple(
        ContactDomain(d, (*(contact_constraint(c) for c in d.contacts), SOCKET),
                      swing_frame=graph.touchdown_frame(d), next=graph.next(d))
        for d in graph.domains)


#: the paper's domains' constraint stacks
DOMAIN_DEFS = domain_defs(DomainGraph.PAPER)


def hip_progress_coefficients(tree: PlanarTree, domain: str) -> tuple[float, float]:
    """(c_knee, c_ankle) of the linearised hip position delta_p_hip = c_k th_k + c_a th_a.

    delta_p_hip is the forward position of the hip relative to the stance ankle with the
    stance foot flat, linearised about upright (REFERENCE.md Sec. 1b): it increases
    during stance in this sign convention (c_k, c_a < 0: the shank rotating forward
    over the foot is a negative ankle angle).  From the tree alone (:func:`build_tree`),
    without the model's dynamics: ``hpcosim mocap process`` needs only these.
    """
    leg = Domain(domain).stance_leg
    q = ca.SX.sym("q", tree.nq)
    ih, ik, ia = (tree.coord_index(c) for c in (leg.hip, leg.knee, leg.ankle))
    rel = frame_pose(tree, q, "hip")[0] - frame_pose(tree, q, leg.ankle_frame)[0]
    # stance foot flat (th_f = 0): th_B = -(th_hip + th_knee + th_ankle)
    rel_flat = ca.substitute(rel, q[tree.coord_index("th_B")], -(q[ih] + q[ik] + q[ia]))
    grad = ca.Function("g", [q], [ca.gradient(rel_flat, q)])(np.zeros(tree.nq))
    g = grad.full().ravel()
    return float(g[ik]), float(g[ia])


class HumanProsthesisModel(HybridModel):
    """The 12-DOF hybrid model.  Besides the :class:`HybridModel` functions it has

        socket_<d>(q, qd, u, lam_foot) -> F_s    (paper eq. Fsocket with the stance-foot
                                                  wrench moved to the known side)

    which equals the socket rows of ``dyn_<d>``'s lam.
    """

    def __init__(self, subject: SubjectConfig, device: DeviceConfig,
                 body: BodyVariation = NOMINAL_BODY,
                 backend: CompileBackend | str = CompileBackend.AUTO,
                 graph: DomainGraph | str = DomainGraph.PAPER) -> None:
        #: the walk's cycle of domains the model is built for
        self.graph = DomainGraph(graph)
        if self.graph == DomainGraph.PAPER:
            # the paper's model has rigid links and ideal drives: its graph reproduces the
            # paper with the drives' rotor inertia left out (docs/subject.md, "armature")
            device = device.without_armature()
        self.subject = subject
        self.device = device
        self.body = body
        tree = build_tree(subject, device, body)
        p = device.prosthesis
        ratios = (1.0, 1.0, 1.0, 1.0, p.knee.gear_ratio.value, p.ankle.gear_ratio.value)
        self.torque_limits = np.array(
            [np.inf] * 4 + [p.knee.torque_limit.value, p.ankle.torque_limit.value])
        self.torque_limits.setflags(write=False)
        name = "hp12" if self.graph == DomainGraph.PAPER else f"hp12_{self.graph}"
        defs = domain_defs(self.graph)
        super().__init__(tree, ACTUATED, ratios, defs, name=name, backend=backend)
        #: each single-support domain's roles resolved to indices (:mod:`hp_model.domains`)
        #: (the roles of the paper's outputs: flat stances ended by a touchdown)
        self.roles: dict[Domain, DomainRoles] = {
            d: domain_roles(self, d) for d in self.graph.domains
            if d.is_flat_stance and self.domains[d].swing_frame is not None}
        # eq. (Fsocket): F_s = (J_s D^-1 J_s^T)^-1 (J_s D^-1 (H - B u - J_f^T lam_f) - Jdot_s qd)
        q, qd, u = self.q, self.qd, self.u
        lam_f = ca.SX.sym("lam_foot", 3)
        h_s = self.constraint_expr((SOCKET,))
        Js = ca.jacobian(h_s, q)
        Jsdqd = ca.jtimes(Js @ qd, q, qd)
        for d in defs:
            if not Domain(d.name).is_flat_stance:
                continue
            Jf = ca.jacobian(self.constraint_expr(d.constraints[:1]), q)
            Hbar = self.H - Jf.T @ lam_f
            X = ca.solve(self.D, ca.horzcat(Js.T, Hbar - ca.DM(self.B) @ u))
            Fs = ca.solve(Js @ X[:, :3], Js @ X[:, 3] - Jsdqd)
            self.functions[f"socket_{d.name}"] = ca.Function(
                f"socket_{d.name}", [q, qd, u, lam_f], [Fs], ["q", "qd", "u", "lam_foot"], ["F_s"])

    def parameter_hash(self) -> str:
        """Hash of every subject and device parameter; artifacts record the model they were
        made for with it (``hp_model.artifacts.canonical_hash``)."""
        from hp_model.artifacts import canonical_hash
        doc: dict[str, object] = {"subject": self.subject.model_dump(mode="json"),
                                  "device": self.device.model_dump(mode="json")}
        if self.graph != DomainGraph.PAPER:  # the paper's graph keeps the existing hashes
            doc["domain_graph"] = self.graph.value
        if not self.body.is_nominal:  # the nominal body keeps the hashes of existing files
            doc["body_variation"] = asdict(self.body)
        return canonical_hash(doc)

    @property
    def prosthesis_mass(self) -> float:
        """Mass of everything below the socket (AMPRO3), kg."""
        return sum(self.tree.body(b).mass for b in ("p_top", "p_shin", "p_foot"))

    def hip_progress_coefficients(self, domain: str) -> tuple[float, float]:
        """(c_knee, c_ankle) of delta_p_hip (:func:`hip_progress_coefficients`)."""
        return hip_progress_coefficients(self.tree, domain)

    def pitch_row(self, frame: str) -> np.ndarray:
        """(nq,) row c with the world pitch of ``frame`` = c . q (rad): exact, the pitch of
        a planar tree's frame is the sum of the pitch coordinates above it.  ``socket``:
        what AMPRO3's IMU on the prosthesis top link measures."""
        pitch = self.frame_expr(frame)[2]
        c = ca.Function("c", [self.q], [ca.gradient(pitch, self.q)])(np.zeros(self.nq))
        row = c.full().ravel()
        if not np.allclose(ca.Function("p", [self.q], [pitch])(np.ones(self.nq)).full(),
                           row.sum()):
            raise ValueError(f"the pitch of frame {frame!r} is not linear in q")
        return row
