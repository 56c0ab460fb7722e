"""Projection of lab-frame motion capture onto the model's sagittal plane.

The model's world frame: x forward (walking direction), z up, y = z x x (to the left);
every angle is a pitch about +y, positive tilting a body's +z axis toward +x
(``R(th) = [[cos, sin], [-sin, cos]]`` maps body (x, z) to world).

A lab frame is described by its up axis and the walking direction, both lab vectors:
sagittal x = p . forward, z = p . up.  Axis strings are ``"+x"``, ``"-z"``, ...; the
walking direction may also be ``"auto"`` (the horizontal direction of the largest net
displacement of a reference trajectory).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from characterization.mocap.take import MocapError

_AXES = {"x": 0, "y": 1, "z": 2}


def axis_vector(spec: str | tuple[float, float, float] | list[float]) -> np.ndarray:
    """A unit lab vector from ``"+y"``/``"-x"``/... or three numbers."""
    if isinstance(spec, str):
        s = spec.strip().lower()
        sign = -1.0 if s.startswith("-") else 1.0
        s = s.lstrip("+-")
        if s not in _AXES:
            raise MocapError(f"axis '{spec}': expected +x, -x, +y, -y, +z or -z")
        v = np.zeros(3)
        v[_AXES[s]] = sign
        return v
    v = np.asarray(spec, dtype=float)
    if v.shape != (3,) or not np.all(np.isfinite(v)) or np.linalg.norm(v) == 0:
        raise MocapError(f"axis {spec!r}: expected three finite numbers, not all zero")
    return v / np.linalg.norm(v)


@dataclass(frozen=True)
class SagittalFrame:
    """Lab directions of the model's world axes (unit 3-vectors): forward (x), up (z) and
    lateral (y = up x forward, to the walker's left)."""

    forward: np.ndarray
    up: np.ndarray

    def __post_init__(self) -> None:
        f, u = np.asarray(self.forward, float), np.asarray(self.up, float)
        f = f - (f @ u) * u
        if np.linalg.norm(f) < 1e-9:
            raise MocapError("walking direction is parallel to the up axis")
        f = f / np.linalg.norm(f)
        for a in (f, u):
            a.setflags(write=False)
        object.__setattr__(self, "forward", f)
        object.__setattr__(self, "up", u)

    @property
    def lateral(self) -> np.ndarray:
        return np.cross(self.up, self.forward)

    @property
    def lab_from_model(self) -> np.ndarray:
        """3x3 rotation whose columns are the model's x, y, z axes in lab coordinates."""
        return np.column_stack([self.forward, self.lateral, self.up])

    def project(self, p: np.ndarray) -> np.ndarray:
        """Lab points (n, 3) -> sagittal (n, 2) = (x forward, z up), metres."""
        return np.column_stack([p @ self.forward, p @ self.up])

    def pitch_from_quaternion(self, quat: np.ndarray, axis: str = "up") -> np.ndarray:
        """Sagittal pitch (rad) of a rigid body whose local axes coincided with the lab axes
        at zero pitch (Motive's default when a rigid body is created in the model's zero
        pose).  ``axis`` is the body axis projected: ``"up"`` (long axis of a leg segment or
        the trunk) or ``"forward"`` (a foot).  ``quat``: (n, 4), scalar last (x, y, z, w),
        normalized here.  NaN where the quaternion is NaN."""
        from scipy.spatial.transform import Rotation  # lazily: 0.4 s of imports

        out = np.full(quat.shape[0], np.nan)
        ok = np.all(np.isfinite(quat), axis=1)
        if not ok.any():
            return out
        R = Rotation.from_quat(quat[ok]).as_matrix()  # (m, 3, 3) lab <- body
        if axis == "up":
            a = R @ self.up  # the body's up axis, in lab coordinates
            out[ok] = np.arctan2(a @ self.forward, a @ self.up)
        elif axis == "forward":
            a = R @ self.forward
            out[ok] = np.arctan2(-(a @ self.up), a @ self.forward)
        else:
            raise MocapError(f"rigid-body axis '{axis}': expected 'up' or 'forward'")
        return out


def auto_forward(trajectory: np.ndarray, up: np.ndarray, source: str, what: str) -> np.ndarray:
    """Walking direction from the net horizontal displacement of a lab trajectory (n, 3)."""
    ok = np.all(np.isfinite(trajectory), axis=1)
    if ok.sum() < 2:
        raise MocapError(f"{source}: cannot detect the walking direction: '{what}' is empty")
    p = trajectory[ok]
    d = p[-1] - p[0]
    d = d - (d @ up) * up
    if np.linalg.norm(d) < 0.5:
        raise MocapError(f"{source}: cannot detect the walking direction ('{what}' moves "
                         f"{np.linalg.norm(d):.2f} m; treadmill?): set 'forward' in the "
                         "mapping config")
    return d / np.linalg.norm(d)


def sagittal_frame(up: str | list[float], forward: str | list[float]) -> SagittalFrame:
    """A :class:`SagittalFrame` from axis specs (``forward`` must not be ``"auto"``)."""
    return SagittalFrame(forward=axis_vector(forward), up=axis_vector(up))
