"""A gait as the tools labs use read it: one stride of its collocation trajectory as CSV
and OpenSim ``.mot`` files (``hpcosim gait export``; formats: :mod:`hp_model.tables`).

The stride is the gait's domains in order (ps, then pns), time from 0 at the start of ps.
The impact between two domains is one instant with two states (before and after); the
files keep the one before (the end of the earlier domain) and drop the first sample of the
later one, because OpenSim refuses a repeated time.  The coordinates are continuous there;
the velocities, torques and ground reactions jump, as they do in the rigid-impact model.

Files written into the folder ``out``:

    stride.csv            time [s]; domain; the 12 coordinates (``COORDS``: x_B, z_B in m,
                          the angles in rad); the actuated joints' torques [N m at the
                          joint: the gear ratio times the motor torque for th_pk, th_pa];
                          each foot's ground reaction in the model's axes: <side>_foot_Fx,
                          _Fz [N], _My [N m about the sole point, about +y], _sole_x,
                          _cop_x [m] (zero / empty while that foot is off the ground);
                          socket_Fx, _Fz [N], _My [N m]: the wrench of the human on the
                          prosthesis at the pin, in the top link's frame (the gait's lam)
    kinematics.mot        time and the 12 coordinates; angles in degrees (inDegrees=yes),
                          translations in m, as OpenSim's coordinates files
    ground_reactions.mot  the ground reactions as OpenSim external loads (below)

Axes: the model is planar with x forward, z up and angles about +y (to the walker's left);
OpenSim's ground has x forward, y up, z to the right.  So OpenSim (x, y, z) = (x, z, -y) of
the model, and a moment M_y of the model is -M_y about OpenSim's z.  The coordinates keep the
model's names and signs (hip flexion negative, knee flexion positive, ankle plantarflexion
positive); an OpenSim model whose sagittal joints turn about +z needs them negated.

ground_reactions.mot columns, per foot (``r`` the prosthesis foot, the model's right leg;
``l`` the human foot): ground_force_<s>_vx, _vy, _vz [N]; ground_force_<s>_px, _py, _pz [m]:
the centre of pressure, x = sole_x - M_y / F_z, y the sole's height (0: on the ground, within
the collocation's tolerance), z = 0 (the planar model has no lateral offset: both feet in
the sagittal plane); ground_torque_<s>_x, _y, _z [N m]: the moment left about that point (0
by the definition of the centre of pressure; -M_y about z where F_z < :data:`MIN_NORMAL` and
the point is the sole's).  A foot off the ground is all zeros.  An OpenSim ExternalForce reads
them with force_identifier ``ground_force_<s>_v``, point_identifier ``ground_force_<s>_p``,
torque_identifier ``ground_torque_<s>_``, all expressed in ground.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from hp_model.artifacts import ArtifactError
from hp_model.domains import PAPER_DOMAINS, Domain
from hp_model.gait_artifact import Gait
from hp_model.human_prosthesis import ACTUATED, SOCKET, HumanProsthesisModel
from hp_model.hybrid import ConstraintKind
from hp_model.tables import Column, MotTable, write_csv, write_mot
from hp_model.tree import JointKind

#: the files :func:`export_gait` writes, in the folder it is given
STRIDE_CSV, KINEMATICS_MOT, GROUND_MOT = "stride.csv", "kinematics.mot", "ground_reactions.mot"
#: below this normal force (N) a centre of pressure is not defined: the point is the sole's
MIN_NORMAL = 1.0


@dataclass(frozen=True)
class Stride:
    """One stride of a gait's trajectory, sample by sample: ``t`` (n,) s from 0, strictly
    increasing; ``domain`` (n,); ``q`` (n, nq); ``u`` (n, nu) motor-side inputs and ``lam``
    (n, n_constraints) constraint wrenches, None when the gait does not store them."""

    t: np.ndarray
    domain: tuple[Domain, ...]
    q: np.ndarray
    u: np.ndarray | None
    lam: np.ndarray | None


def _field(gait: Gait, d: Domain, name: str, rows: int, src: str) -> np.ndarray | None:
    """``trajectory.<d>.<name>`` as (rows, P), or None when the gait does not store it."""
    a = gait.trajectory[d].get(name)
    if a is None:
        return None
    a = np.asarray(a, dtype=float)
    if a.ndim != 2 or a.shape[0] != rows:
        raise ArtifactError(f"{src}: field 'trajectory.{d}.{name}': shape {a.shape}, "
                            f"expected ({rows}xP)")
    return a


def _domain_samples(gait: Gait, model: HumanProsthesisModel, d: Domain, src: str
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray | None, np.ndarray | None]:
    """(t, q, u, lam) of one domain, checked: t (P,) strictly increasing, the others (., P)."""
    if d not in gait.trajectory or "t" not in gait.trajectory[d]:
        raise ArtifactError(f"{src}: field 'trajectory.{d}': missing; the export reads the "
                            "collocation trajectory `hpcosim gait fit` stores")
    t = np.asarray(gait.trajectory[d]["t"], dtype=float)
    if t.ndim != 1 or t.size < 2 or not np.all(np.diff(t) > 0) or not np.isfinite(t).all():
        raise ArtifactError(f"{src}: field 'trajectory.{d}.t': not a strictly increasing "
                            "time of at least 2 samples")
    q = _field(gait, d, "q", model.nq, src)
    if q is None:
        raise ArtifactError(f"{src}: field 'trajectory.{d}.q': missing")
    u = _field(gait, d, "u", len(ACTUATED), src)
    lam = _field(gait, d, "lam", model.domains[d].n_constraints, src)
    for name, a in (("q", q), ("u", u), ("lam", lam)):
        if a is not None and a.shape[1] != t.size:
            raise ArtifactError(f"{src}: field 'trajectory.{d}.{name}': {a.shape[1]} "
                                f"samples, 't' has {t.size}")
    return t - t[0], q, u, lam


def stride(gait: Gait, model: HumanProsthesisModel, src: str = "gait") -> Stride:
    """One stride of ``gait``'s trajectory (module docstring); a gait without one, or with
    a field of the wrong shape, is an :class:`ArtifactError` naming ``src`` and the field."""
    ts: list[np.ndarray] = []
    qs: list[np.ndarray] = []
    us: list[np.ndarray | None] = []
    lams: list[np.ndarray | None] = []
    doms: list[Domain] = []
    t0 = 0.0
    for i, d in enumerate(PAPER_DOMAINS):
        t, q, u, lam = _domain_samples(gait, model, d, src)
        keep = slice(1 if i else 0, None)  # the impact's second state: dropped
        ts.append(t[keep] + t0)
        doms.extend([d] * (t.size - (1 if i else 0)))
        qs.append(q[:, keep].T)
        us.append(None if u is None else u[:, keep].T)
        lams.append(None if lam is None else lam[:, keep].T)
        t0 += float(t[-1])
    return Stride(t=np.concatenate(ts), domain=tuple(doms), q=np.vstack(qs), u=_stacked(us),
                  lam=_stacked(lams))


def _stacked(parts: list[np.ndarray | None]) -> np.ndarray | None:
    """The domains' rows stacked, or None when a domain lacks the field."""
    have = [p for p in parts if p is not None]
    return np.vstack(have) if len(have) == len(parts) else None


@dataclass(frozen=True)
class FootReaction:
    """One foot's ground reaction over a stride (n,) each, zero while it is off the ground:
    ``fx``, ``fz`` (N), ``my`` (N m about the sole point, about the model's +y), ``sole_x``,
    ``cop_x`` (m; NaN off the ground), ``torque`` (N m about the centre of pressure, +y)."""

    side: str
    right: bool
    fx: np.ndarray
    fz: np.ndarray
    my: np.ndarray
    sole_x: np.ndarray
    sole_z: np.ndarray
    cop_x: np.ndarray
    torque: np.ndarray


def foot_reactions(model: HumanProsthesisModel, s: Stride) -> list[FootReaction]:
    """Each foot's ground reaction (the stance foot's constraint wrench, at its sole frame)
    over the stride ``s`` (which must have ``lam``), in the order of the domains."""
    if s.lam is None:
        raise ValueError("the stride has no constraint wrenches")
    frames = model.numeric()["frames"]
    zero = np.zeros(model.nq)
    n = s.t.size
    out = []
    for d in PAPER_DOMAINS:
        dom = model.domains[d]
        foot = next(c for c in dom.constraints if c.kind == ConstraintKind.FRAME)
        rows = dom.wrench_slice(foot.name)
        sole = model.roles[d].stance_frame_index
        fx, fz, my, sx, sz = (np.zeros(n) for _ in range(5))
        cop, torque = np.full(n, np.nan), np.zeros(n)
        for k in np.flatnonzero([dk == d for dk in s.domain]):
            pose = frames(s.q[k], zero)[0]  # a reused buffer: read what is needed now
            sx[k], sz[k] = float(pose[0, sole]), float(pose[1, sole])
            fx[k], fz[k], my[k] = s.lam[k, rows]
            cop[k] = sx[k] - my[k] / fz[k] if fz[k] > MIN_NORMAL else sx[k]
            torque[k] = my[k] - (sx[k] - cop[k]) * fz[k]
        out.append(FootReaction(d.stance_leg.side, d.is_prosthesis_stance, fx, fz, my, sx,
                                sz, cop, torque))
    return out


def _ground_table(feet: list[FootReaction], t: np.ndarray) -> MotTable:
    """The OpenSim external loads of ``feet`` (module docstring: axes and names)."""
    labels: list[str] = []
    cols: list[np.ndarray] = []
    zero = np.zeros(t.size)
    for f in feet:
        s = "r" if f.right else "l"
        on = ~np.isnan(f.cop_x)
        labels += [f"ground_force_{s}_v{a}" for a in "xyz"]
        labels += [f"ground_force_{s}_p{a}" for a in "xyz"]
        labels += [f"ground_torque_{s}_{a}" for a in "xyz"]
        cols += [f.fx, f.fz, zero, np.where(on, f.cop_x, 0.0), np.where(on, f.sole_z, 0.0),
                 zero, zero, zero, -f.torque]
    return MotTable("GroundReactions", t, tuple(labels), np.column_stack(cols),
                    in_degrees=True, comments=(
                        "Units are S.I. units (second, meters, Newtons, ...)",
                        "Ground frame: x forward, y up, z right (the planar model's x, z, -y)"))


def _coordinate_columns(model: HumanProsthesisModel, q: np.ndarray) -> list[Column]:
    rot = angle_flags(model)
    return [Column(c, "rad" if r else "m", q[:, i])
            for i, (c, r) in enumerate(zip(model.coord_names, rot, strict=True))]


def angle_flags(model: HumanProsthesisModel) -> list[bool]:
    """Whether each coordinate is an angle (a revolute joint's; a planar joint's third,
    its pitch) or a length (a planar joint's x, z), in ``coord_names`` order."""
    return [b.joint is JointKind.REVOLUTE or i == 2
            for b in model.tree.bodies for i in range(len(b.coords))]


def _force_columns(model: HumanProsthesisModel, s: Stride,
                   feet: list[FootReaction]) -> list[Column]:
    cols: list[Column] = []
    if s.u is not None:
        joint = s.u @ np.asarray(model.B).T  # generalized forces (n, nq): ratio x motor
        for c in ACTUATED:
            cols.append(Column(f"{c}_torque", "N m", joint[:, model.coord_names.index(c)]))
    for f in feet:
        p = f"{f.side}_foot"
        cols += [Column(f"{p}_Fx", "N", f.fx), Column(f"{p}_Fz", "N", f.fz),
                 Column(f"{p}_My", "N m", f.my),
                 Column(f"{p}_sole_x", "m", np.where(np.isnan(f.cop_x), np.nan, f.sole_x)),
                 Column(f"{p}_cop_x", "m", f.cop_x)]
    if s.lam is not None:
        socket = np.zeros((s.t.size, 3))
        for d in PAPER_DOMAINS:
            rows = model.domains[d].wrench_slice(SOCKET.name)
            on = np.array([dk == d for dk in s.domain])
            socket[on] = s.lam[on][:, rows]
        cols += [Column("socket_Fx", "N", socket[:, 0]), Column("socket_Fz", "N", socket[:, 1]),
                 Column("socket_My", "N m", socket[:, 2])]
    return cols


def export_gait(gait: Gait, model: HumanProsthesisModel, out: str | os.PathLike[str],
                src: str = "gait") -> list[Path]:
    """Write one stride of ``gait`` into the folder ``out`` (created if missing; module
    docstring); returns the files written (no ground reactions without ``lam``)."""
    gait.check_model(model.parameter_hash(), src)
    s = stride(gait, model, src)
    feet = foot_reactions(model, s) if s.lam is not None else []
    folder = Path(out)
    folder.mkdir(parents=True, exist_ok=True)
    written = [folder / STRIDE_CSV, folder / KINEMATICS_MOT]
    write_csv(written[0], [Column("time", "s", s.t), Column("domain", None, list(s.domain)),
                           *_coordinate_columns(model, s.q), *_force_columns(model, s, feet)])
    rot = np.array(angle_flags(model))
    write_mot(written[1], MotTable("Coordinates", s.t, tuple(model.coord_names),
                                   np.where(rot, np.degrees(s.q), s.q), in_degrees=True,
                                   comments=(
                                       "Units are S.I. units (second, meters, Newtons, ...)",
                                       "Angles are in degrees.")))
    if feet:
        written.append(folder / GROUND_MOT)
        write_mot(written[2], _ground_table(feet, s.t))
    return written
