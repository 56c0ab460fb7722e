"""The walker for Foxglove (issue 21): its frames as ``foxglove.FrameTransforms``, a
``foxglove.SceneUpdate`` of primitives, and the gait's reference at the recorded phase.

Frames come from the model's own forward kinematics (:meth:`hp_model.HumanProsthesisModel.
numeric` ``frames``: world x, z and pitch of every named frame, the source
:mod:`orchestrator.experiments.animation` draws from).  In 3-D: x forward, z up, y = z x x (to the
walker's left), a planar pitch theta is a rotation by theta about +y (quaternion
(0, sin theta/2, 0, cos theta/2)), so a body point (px, pz) lies at
(x + cos th px + sin th pz, 0, z - sin th px + cos th pz).  The transforms form a tree
rooted at ``world`` (:func:`frame_parents`): each frame's parent is the frame standing for
its body (the body's origin frame) or, for that one, the frame standing for the nearest
ancestor body carrying frames; each transform is the child's pose in its parent's frame.

The scene (all in ``world``): the human (trunk, left leg, the right thigh) in blue, the
iWalk in grey, the prosthesis (socket to foot) in orange, joints as spheres, the ground as
a thin box under the walker, the socket force on the prosthesis as a red arrow at the
socket (1 m per :data:`orchestrator.loop.walker_figure.FORCE_SCALE` N), and a text line (time,
domain, phase, step).  Every message is complete (no state across messages), so a viewer
that seeks shows the right picture.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import numpy as np

from hp_model.domains import PAPER_DOMAINS, Domain
from hp_model.human_prosthesis import HumanProsthesisModel
from orchestrator.loop.plant import Vector
from orchestrator.loop.walker_figure import FORCE_SCALE, HUMAN, IWALK, PROSTHESIS

TRANSFORMS_TOPIC = "/walker/tf"
SCENE_TOPIC = "/walker/scene"
REFERENCE_TOPIC = "/walker/reference"
WORLD = "world"
PERIOD = 0.01  # s of simulation time between two walker messages
GROUND = (6.0, 1.0, 0.02)  # ground box size x, y, z [m], its top at z = 0
_FORCE_KEYS = ("Fx", "Fz", "My")


def frame_parents(model: HumanProsthesisModel) -> dict[str, str]:
    """Parent frame of each of the model's named frames (module docstring); ``world`` for
    the frame(s) of the root body."""
    tree = model.tree
    on_body: dict[str, list[Any]] = {}
    for f in tree.frames:
        on_body.setdefault(f.body, []).append(f)

    def anchor(body: str) -> str | None:
        fs = on_body.get(body, [])
        origin = [f for f in fs if tuple(f.point) == (0.0, 0.0)]
        return (origin or fs)[0].name if fs else None

    parents: dict[str, str] = {}
    for f in tree.frames:
        a = anchor(f.body)
        if a is not None and a != f.name:
            parents[f.name] = a
            continue
        b = tree.body(f.body).parent
        while b is not None and anchor(b) is None:
            b = tree.body(b).parent
        parents[f.name] = WORLD if b is None else str(anchor(b))
    return parents


def _rgba(hex_colour: str, a: float = 1.0) -> tuple[float, float, float, float]:
    h = hex_colour.lstrip("#")
    return (int(h[0:2], 16) / 255, int(h[2:4], 16) / 255, int(h[4:6], 16) / 255, a)


def _set_colour(c: Any, rgba: tuple[float, float, float, float]) -> None:
    c.r, c.g, c.b, c.a = rgba


def _bernstein(m: int) -> Callable[[float], np.ndarray]:
    """s -> the m+1 Bernstein basis values at scalar s (:func:`hp_model.bezier.basis`)."""
    i = np.arange(m + 1)
    c = np.array([math.comb(m, k) for k in i], float)
    return lambda s: c * s**i * (1.0 - s) ** (m - i)


class WalkerFoxglove:
    """Builds the Foxglove messages of one walker state (module docstring).  ``gait`` and
    ``tube`` (optional) give :meth:`reference` its desired angles and force tube.

    Each message is a copy of a template built once (names, colours, sizes) with only the
    numbers of the state filled in: about 0.1 ms per state (transforms, scene and reference
    together), paid every :data:`PERIOD` in the recorder's deferred serialization."""

    def __init__(self, model: HumanProsthesisModel, gait: Any = None, tube: Any = None
                 ) -> None:
        from bus_schemas.recording.foxglove import foxglove_message_class

        self._frames = model.numeric()["frames"]
        self._zero = np.zeros(model.nq)
        self.names: tuple[str, ...] = tuple(model.frame_names)
        self.parents = frame_parents(model)
        index = {n: i for i, n in enumerate(self.names)}
        self._child = np.array([index[n] for n in self.names])
        self._parent = np.array([index.get(self.parents[n], -1) for n in self.names])
        self._trunk = float(model.subject.lengths.trunk)
        self._ib = model.coord_names.index("th_B")
        self._socket = index["socket"]
        self._hip = index["hip"]
        self._pose_key: np.ndarray | None = None
        self._pose = np.zeros((3, len(self.names)))
        # transforms: every frame in its parent (names fixed, numbers per state)
        self._tf = foxglove_message_class("foxglove.FrameTransforms")()
        for n in self.names:
            tf = self._tf.transforms.add()
            tf.parent_frame_id, tf.child_frame_id = self.parents[n], n
        # scene: the chains as line strips (each point a frame index; -1 the head), the
        # frames and the head as spheres, the force arrow, a text; the ground
        self._chains: list[list[int]] = []
        self._scene = foxglove_message_class("foxglove.SceneUpdate")()
        walker, ground = self._scene.entities.add(), self._scene.entities.add()
        walker.frame_id, walker.id = WORLD, "walker"
        ground.frame_id, ground.id = WORLD, "ground"
        for colour, chains in (*((c, ch) for c, ch in (HUMAN, IWALK, PROSTHESIS)),
                               (HUMAN[0], (("hip", "head"),))):
            for chain in chains:
                ln = walker.lines.add()
                ln.type = 0  # LINE_STRIP
                ln.pose.orientation.w = 1.0
                ln.thickness = 0.05 if "head" in chain else 0.03
                _set_colour(ln.color, _rgba(colour))
                self._chains.append([index.get(n, -1) for n in chain])
                for _ in chain:
                    ln.points.add()
        for n in (*self.names, "head"):
            sp = walker.spheres.add()
            sp.pose.orientation.w = 1.0
            sp.size.x = sp.size.y = sp.size.z = 0.16 if n == "head" else 0.045
            owner = PROSTHESIS if n.startswith("p_") or n == "socket" else HUMAN
            _set_colour(sp.color, _rgba(owner[0]))
        arrow = walker.arrows.add()
        arrow.shaft_diameter, arrow.head_diameter = 0.015, 0.04
        _set_colour(arrow.color, _rgba("#b00020"))
        text = walker.texts.add()
        text.pose.orientation.w = 1.0
        text.billboard, text.font_size, text.scale_invariant = True, 14.0, True
        _set_colour(text.color, (0.1, 0.1, 0.1, 1.0))
        cube = ground.cubes.add()
        cube.pose.position.z = -GROUND[2] / 2
        cube.pose.orientation.w = 1.0
        cube.size.x, cube.size.y, cube.size.z = GROUND
        _set_colour(cube.color, _rgba("#5a4a3a"))
        # reference: the gait's knee and ankle rows per domain, the tube's Bezier bounds
        self.gait, self.tube = gait, tube
        self._ref: dict[str, tuple[tuple[str, ...], np.ndarray, Callable]] = {}
        if gait is not None:
            for d in PAPER_DOMAINS:
                joints = tuple(j for j, c in (("knee", "th_pk"), ("ankle", "th_pa"))
                               if c in d.y2_coords)
                rows = [d.y2_coords.index(c) for c in ("th_pk", "th_pa")
                        if c in d.y2_coords]
                alpha = np.asarray(gait.params[d].alpha, float)[rows]
                self._ref[d] = (joints, alpha, _bernstein(alpha.shape[1] - 1))
        if tube is not None:
            self._tube = (tube.tau_lo, tube.tau_hi, tube.nominal, tube.widened_lower,
                          tube.widened_upper, _bernstein(tube.nominal.shape[1] - 1),
                          _bernstein(tube.lower.shape[1] - 1))

    def pose(self, q: Vector) -> np.ndarray:
        """(3, frames) world x [m], z [m], pitch [rad] of every frame (the last q and its
        pose are kept: the transforms and the scene of one state evaluate the model once)."""
        qa = np.array(q, float)
        if self._pose_key is None or not np.array_equal(qa, self._pose_key):
            self._pose = np.array(self._frames(qa, self._zero)[0], float)
            self._pose_key = qa
        return self._pose

    # -- transforms
    def transforms(self, ns: int, q: Vector) -> bytes:
        """Serialized ``foxglove.FrameTransforms``: every frame in its parent at time
        ``ns`` [ns]."""
        p = self.pose(q)
        par = self._parent
        pp = np.where(par >= 0, p[:, np.maximum(par, 0)], 0.0)  # parents' poses (world: 0)
        d = p - pp
        c, s = np.cos(pp[2]), np.sin(pp[2])
        x = (c * d[0] - s * d[1]).tolist()  # R(parent pitch)^T (p_child - p_parent)
        z = (s * d[0] + c * d[1]).tolist()
        half = 0.5 * d[2]
        qy, qw = np.sin(half).tolist(), np.cos(half).tolist()
        sec, nsec = divmod(int(ns), 1_000_000_000)
        msg = type(self._tf)()
        msg.CopyFrom(self._tf)
        for k, tf in enumerate(msg.transforms):
            tf.timestamp.seconds, tf.timestamp.nanos = sec, nsec
            tr, rot = tf.translation, tf.rotation
            tr.x, tr.z = x[k], z[k]
            rot.y, rot.w = qy[k], qw[k]
        return msg.SerializeToString()

    # -- scene
    def scene(self, ns: int, t: float, q: Vector, socket_force: Vector | None, domain: str,
              tau: float, step: int) -> bytes:
        """Serialized ``foxglove.SceneUpdate`` of the walker at log time ``ns`` [ns]
        (simulation time ``t`` [s] in its text); ``socket_force`` (Fx, Fz [N], My [N m]) in
        the prosthesis top link's frame."""
        p = self.pose(q)
        xs, zs = p[0].tolist(), p[1].tolist()
        hx, hz = xs[self._hip], zs[self._hip]
        th = float(q[self._ib])
        head = (hx + self._trunk * math.sin(th), hz + self._trunk * math.cos(th))
        xs.append(head[0])  # index -1: the head
        zs.append(head[1])
        sec, nsec = divmod(int(ns), 1_000_000_000)
        msg = type(self._scene)()
        msg.CopyFrom(self._scene)
        walker, ground = msg.entities
        for e in (walker, ground):
            e.timestamp.seconds, e.timestamp.nanos = sec, nsec
        for ln, chain in zip(walker.lines, self._chains, strict=True):
            for pt, i in zip(ln.points, chain, strict=True):
                pt.x, pt.z = xs[i], zs[i]
        for k, sp in enumerate(walker.spheres):
            pos = sp.pose.position
            pos.x, pos.z = xs[k], zs[k]  # the last sphere: the head (index -1 = k)
        if not (socket_force is not None and self._arrow(
                walker.arrows[0], (xs[self._socket], zs[self._socket]),
                float(p[2, self._socket]), float(socket_force[0]), float(socket_force[1]))):
            del walker.arrows[:]
        text = walker.texts[0]
        text.pose.position.x, text.pose.position.z = hx, head[1] + 0.25
        text.text = f"t {t:.2f} s  {domain}  tau {tau:.2f}  step {step}"
        ground.cubes[0].pose.position.x = hx
        return msg.SerializeToString()

    @staticmethod
    def _arrow(a: Any, at: tuple[float, float], pitch: float, fx: float, fz: float) -> bool:
        """The socket force as arrow ``a`` from the socket: (fx, fz) in the top link's frame
        rotated to world, 1 m per ``FORCE_SCALE`` N; False if it is too short to draw."""
        c, s = math.cos(pitch), math.sin(pitch)
        wx, wz = c * fx + s * fz, -s * fx + c * fz
        length = math.hypot(wx, wz) / FORCE_SCALE
        if not length > 1e-3:
            return False
        a.pose.position.x, a.pose.position.z = at
        half = 0.5 * math.atan2(-wz, wx)  # rotation about +y turning +x onto (wx, 0, wz)
        a.pose.orientation.y, a.pose.orientation.w = math.sin(half), math.cos(half)
        head = min(0.06, 0.5 * length)
        a.shaft_length, a.head_length = length - head, head
        return True

    # -- reference
    def reference(self, t: float, domain: str, tau: float) -> dict[str, Any]:
        """``/walker/reference`` (``hpcosim.WalkerReference``) at phase ``tau``: the gait's
        desired knee and ankle angles [rad] (null where the joint is not an output or
        without a gait) and the force tube's bounds on F_s [N, N m] (ps, with a tube; what
        :meth:`hp_model.force_tube.ForceTube.box` gives: c - r and c + r)."""
        out: dict[str, Any] = {"t": t, "domain": domain, "tau": tau, "knee": None,
                               "ankle": None, "socket_lower": None, "socket_upper": None}
        if domain in self._ref:
            joints, alpha, basis = self._ref[domain]
            s = min(max(float(tau), 0.0), 1.0)
            out.update(zip(joints, (alpha @ basis(s)).tolist(), strict=True))
        if self.tube is not None and domain == Domain.PS:
            t_lo, t_hi, nominal, lower, upper, bn, bd = self._tube
            s = min(max((float(tau) - t_lo) / (t_hi - t_lo), 0.0), 1.0)
            f = nominal @ bn(s)
            lo, hi = lower @ bd(s), upper @ bd(s)
            mid = 0.5 * (lo + hi)
            lower, upper = f + np.minimum(lo, mid), f + np.maximum(hi, mid)
            out["socket_lower"] = dict(zip(_FORCE_KEYS, lower.tolist(), strict=True))
            out["socket_upper"] = dict(zip(_FORCE_KEYS, upper.tolist(), strict=True))
        return out


__all__ = ["PERIOD", "REFERENCE_TOPIC", "SCENE_TOPIC", "TRANSFORMS_TOPIC", "WORLD",
           "WalkerFoxglove", "frame_parents"]
