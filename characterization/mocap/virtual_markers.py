"""Virtual markers: points a lab's model builds from its markers in every frame, named in
the mapping's ``[virtual_markers]`` and then used as any marker is (limbs, joints,
segmentation, landmarks).  A take whose markers include anatomical landmarks in walking
(both femoral epicondyles, both malleoli, the pelvis) gives each leg segment its anatomical
axis in every frame this way: hip centre -> knee centre -> ankle centre, the model's own
segment axes, with no standing pitch to assume.

Two kinds (:class:`~characterization.mocap.mapping.MocapMapping`):

- ``NAME = ["A", "B", ...]``: the mean of the markers, frame by frame (a knee centre from
  the lateral and medial epicondyles);
- ``NAME = { asis = ["LASI", "RASI"], sacrum = ["LPSI", "RPSI"] }``: the hip joint centre of
  Harrington et al. 2007 (J Biomech 40: 595-602) on the pelvis's midline: behind the ASIS
  midpoint by 0.24 PD + 9.9 mm and below it by 0.30 PW + 10.9 mm along the pelvis's own
  axes (PW: ASIS to ASIS; PD: their midpoint to the sacrum, the mean of ``sacrum``).  Its
  lateral offset (0.33 PW + 7.3 mm) is left out: the sagittal processing projects it away,
  so one point serves both hips.

A frame where any marker it is built from is missing is missing (NaN) in the virtual marker.
Positions in the take's lab frame and units (m).
"""

from __future__ import annotations

import numpy as np

from characterization.mocap.mapping import MocapMapping, Pelvis
from characterization.mocap.take import MocapError, Take

#: Harrington et al. 2007's regression (mm, of PW and PD in mm): (behind, below)
HARRINGTON = ((0.24, 9.9), (0.30, 10.9))


def with_virtual_markers(take: Take, mapping: MocapMapping) -> Take:
    """``take`` with the mapping's virtual markers added, in the mapping's order (one may be
    built from those before it; ``take`` itself when it names none); a :class:`MocapError`
    naming the entry when a marker it is built from is not in the take or its name is
    already a column of the take."""
    for name, spec in mapping.virtual_markers.items():  # in order: one may use the ones before
        if name in take.markers or name in take.rigid_body_markers:
            raise MocapError(f"{take.source}: virtual_markers.{name}: the take already has a "
                             f"marker '{name}'; name the virtual marker otherwise")
        what = f"virtual_markers.{name}"
        point = (hip_centre_track(take, spec, mapping, what)
                 if isinstance(spec, Pelvis) else
                 np.mean([_marker(take, m, what) for m in spec], axis=0))
        take = take.replace(markers={**take.markers, name: point})
    return take


def hip_centre_track(take: Take, pelvis: Pelvis, mapping: MocapMapping, what: str
                     ) -> np.ndarray:
    """The hip joint centre on the pelvis's midline in every frame (n, 3), m (module
    docstring); the sign of the pelvis's normal toward the mean of the feet's markers that
    ``mapping`` names (without any, the file's down axis); ``what``: the mapping entry the
    errors name."""
    feet = _feet(take, mapping)
    a0, a1 = (_marker(take, m, what) for m in pelvis.asis)
    sacrum = np.mean([_marker(take, m, what) for m in pelvis.sacrum], axis=0)
    mid = 0.5 * (a0 + a1)
    below = _file_down(take) if feet is None else feet - np.nanmean(mid, axis=0)
    width = 1000.0 * np.linalg.norm(a0 - a1, axis=1, keepdims=True)  # mm
    depth = 1000.0 * np.linalg.norm(mid - sacrum, axis=1, keepdims=True)
    forward = _unit(mid - sacrum)
    lateral = a0 - a1
    lateral = _unit(lateral - np.sum(lateral * forward, axis=1, keepdims=True) * forward)
    down = np.cross(forward, lateral)
    down *= np.where(down @ below >= 0.0, 1.0, -1.0)[:, None]
    (kb, cb), (kd, cd) = HARRINGTON
    return mid - (kb * depth + cb) / 1000.0 * forward + (kd * width + cd) / 1000.0 * down


def _marker(take: Take, name: str, what: str) -> np.ndarray:
    try:
        return take.marker(name)
    except MocapError as e:
        raise MocapError(f"{e} (mapping entry {what})") from None


def _unit(v: np.ndarray) -> np.ndarray:
    with np.errstate(invalid="ignore", divide="ignore"):
        return v / np.linalg.norm(v, axis=1, keepdims=True)


def _feet(take: Take, mapping: MocapMapping) -> np.ndarray | None:
    """The mean lab position of the feet's markers (the mapping's foot limbs and
    segmentation markers that the take has); None without one."""
    names = [m for limb in ("l_foot", "p_foot") if limb in mapping.limbs
             for m in (mapping.limbs[limb].markers or ())]
    if mapping.segmentation is not None:
        names += [mapping.segmentation.human_foot_marker,
                  mapping.segmentation.prosthesis_foot_marker]
    feet = [take.markers[n] for n in names if n in take.markers]
    if not feet:
        return None
    p = np.nanmean(np.concatenate(feet, axis=0), axis=0)
    return p if np.all(np.isfinite(p)) else None


def _file_down(take: Take) -> np.ndarray:
    """The file's down axis (the opposite of its up axis, e.g. "+z")."""
    out = np.zeros(3)
    out["xyz".index(take.up_axis[-1])] = -1.0 if take.up_axis.startswith("+") else 1.0
    return out
