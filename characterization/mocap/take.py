"""A motion-capture take in memory, whatever file it came from.

Positions are metres in the file's own (lab) axes; which lab axis is up and which is the
walking direction is decided later (:mod:`characterization.mocap.sagittal`).  A lost sample is
NaN in every coordinate.  Rigid-body orientations are unit quaternions (x, y, z, w), scalar
last, mapping the rigid body's local axes to the lab axes; a lost rigid body is NaN.

A file may also hold what a lab's model computed from the markers, stored as points beside
them (Vicon's POINT:ANGLES, FORCES, MOMENTS, POWERS, ...): those are :class:`ModelOutput`
values, never markers.

Arrays are read-only; a :class:`Take` is never modified, derive a new one with
:meth:`Take.replace`.
"""

from __future__ import annotations

import difflib
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from types import MappingProxyType
from typing import Any

import numpy as np


class MocapError(ValueError):
    """Motion-capture input that cannot be used; the message is one line naming the file
    and the column or frame."""


def _frozen(a: np.ndarray) -> np.ndarray:
    a = np.array(a, dtype=float)
    a.setflags(write=False)
    return a


@dataclass(frozen=True)
class RigidBodyTrack:
    """One rigid body: position (n, 3) m and orientation (n, 4) quaternion x, y, z, w in lab
    axes; ``mean_error`` (n,) m if the file has it."""

    position: np.ndarray
    quaternion: np.ndarray
    mean_error: np.ndarray | None = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "position", _frozen(self.position))
        object.__setattr__(self, "quaternion", _frozen(self.quaternion))
        if self.mean_error is not None:
            object.__setattr__(self, "mean_error", _frozen(self.mean_error))

    @property
    def tracked(self) -> np.ndarray:
        """(n,) bool: the orientation is present in that frame."""
        return np.all(np.isfinite(self.quaternion), axis=1)


@dataclass(frozen=True)
class LabEvent:
    """A gait event the lab put in the file (C3D EVENT): label (e.g. "Foot Strike",
    "Foot Off"), context (e.g. "Left", "Right"), time (s, on the take's time axis)."""

    label: str
    context: str
    time: float


@dataclass(frozen=True)
class ModelOutput:
    """A quantity a lab's model computed and the file stores as a point: ``kind`` the group
    that names it (the C3D POINT parameter, e.g. "ANGLES", "MOMENTS", "MODELED_MARKERS"),
    ``unit`` the file's unit for that kind (e.g. "deg", "Nmm"; "" if the file gives none),
    ``values`` (n, 3) in that unit as the file has them, NaN where the file has none."""

    kind: str
    unit: str
    values: np.ndarray

    def __post_init__(self) -> None:
        object.__setattr__(self, "values", _frozen(self.values))


@dataclass(frozen=True)
class Take:
    """A take: frame times, markers and rigid bodies.

    ``markers``: reconstructed markers, name -> (n, 3) m.  ``rigid_body_markers``: positions
    solved from rigid bodies (Motive's "Rigid Body Marker"), name -> (n, 3) m.
    ``up_axis`` is the file's up axis: the file's own word where it has one
    (``up_axis_source`` names it, e.g. C3D's ``"POINT:Y_SCREEN"``), else the format's
    default (``"+y"`` Motive and TRC, ``"+z"`` C3D; ``up_axis_source`` empty).
    ``model_outputs``: name -> :class:`ModelOutput`, what the lab's model computed (not
    markers: :meth:`marker` refuses them by name).
    """

    source: str
    frame_rate: float
    time: np.ndarray
    markers: Mapping[str, np.ndarray]
    rigid_bodies: Mapping[str, RigidBodyTrack] = field(default_factory=dict)
    rigid_body_markers: Mapping[str, np.ndarray] = field(default_factory=dict)
    up_axis: str = "+y"
    metadata: Mapping[str, str] = field(default_factory=dict)
    events: tuple[LabEvent, ...] = ()
    model_outputs: Mapping[str, ModelOutput] = field(default_factory=dict)
    up_axis_source: str = ""

    def __post_init__(self) -> None:
        object.__setattr__(self, "time", _frozen(self.time))
        n = self.time.shape[0]
        outputs = {k: o.values for k, o in self.model_outputs.items()}
        for what, d in (("marker", self.markers), ("rigid body marker", self.rigid_body_markers),
                        ("model output", outputs)):
            for k, v in d.items():
                if np.shape(v) != (n, 3):
                    raise MocapError(f"{self.source}: {what} '{k}' has shape {np.shape(v)}, "
                                     f"expected ({n}, 3)")
        object.__setattr__(self, "model_outputs", MappingProxyType(dict(self.model_outputs)))
        object.__setattr__(self, "markers",
                           MappingProxyType({k: _frozen(v) for k, v in self.markers.items()}))
        object.__setattr__(self, "rigid_body_markers", MappingProxyType(
            {k: _frozen(v) for k, v in self.rigid_body_markers.items()}))
        object.__setattr__(self, "rigid_bodies", MappingProxyType(dict(self.rigid_bodies)))
        object.__setattr__(self, "metadata", MappingProxyType(dict(self.metadata)))

    @property
    def n_frames(self) -> int:
        return int(self.time.shape[0])

    def marker(self, name: str) -> np.ndarray:
        """A marker by name: reconstructed markers first, then rigid-body markers; a name
        that matches one marker only when case is ignored is that marker; a model output's
        name is a :class:`MocapError` saying so; else a :class:`MocapError` with the
        closest names ("did you mean")."""
        for d in (self.markers, self.rigid_body_markers):
            if name in d:
                return d[name]
        if name in self.model_outputs:
            raise MocapError(f"{self.source}: '{name}' is not a marker: the lab's model "
                             f"computed it (POINT:{self.model_outputs[name].kind})")
        key = _lookup(name, [*self.markers, *self.rigid_body_markers], self.source, "marker")
        return self.markers[key] if key in self.markers else self.rigid_body_markers[key]

    def rigid_body(self, name: str) -> RigidBodyTrack:
        """A rigid body by name (case-insensitive when unambiguous, as :meth:`marker`)."""
        if name in self.rigid_bodies:
            return self.rigid_bodies[name]
        return self.rigid_bodies[_lookup(name, list(self.rigid_bodies), self.source,
                                         "rigid body")]

    def replace(self, **changes: Any) -> Take:
        """A copy with some fields replaced (e.g. markers with a gap cut in)."""
        return replace(self, **changes)


def _lookup(name: str, names: list[str], source: str, what: str) -> str:
    """The one name equal to ``name`` ignoring case, else a MocapError naming the closest."""
    same = [n for n in names if n.casefold() == name.casefold()]
    if len(same) == 1:
        return same[0]
    close = same or difflib.get_close_matches(name, names, n=3, cutoff=0.6)
    hint = f" (did you mean {', '.join(repr(c) for c in close)}?)" if close else ""
    raise MocapError(f"{source}: no {what} column '{name}'{hint}")
