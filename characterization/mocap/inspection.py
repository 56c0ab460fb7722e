"""What a take holds, and a mapping to start from (``hpcosim mocap inspect``, issue 19).

:func:`summarize` lists the markers and rigid bodies with their valid frames and longest
gap, the frame rate and length, what the lab's model computed (a processed C3D's angles,
moments, ...: counted, never taken for markers), and a guess of the axes: up is the file's
own up axis where it has one (C3D's POINT:Y_SCREEN), else the lab axis along which the
markers span the most per frame (a standing body is taller than wide or deep; its sign is
the file format's default); ``mocap process`` checks either against the trunk and the
feet.  The walking axis is the one the markers' centroid travels along the most.
:func:`mapping_skeleton` writes a mapping TOML with every limb, joint and the segmentation
filled by name patterns where the names allow it and ``"TODO"`` where they do not, every
column name of the take listed in comments, for the user to edit.  A lower-body marker set
(Plug-in Gait's LASI/RASI/LPSI/RPSI, no marker on the trunk) gets the pelvis as the trunk:
a PSIS -> ASIS pair along the hat's forward axis.
"""

from __future__ import annotations

import re
import warnings
from dataclasses import dataclass

import numpy as np

from characterization.mocap.landmark_names import leg_landmarks, pelvis_landmarks
from characterization.mocap.mapping import JOINTS, LIMBS
from characterization.mocap.take import Take

TODO = "TODO"
#: m: less net travel of the markers than this is not a walking direction (a treadmill)
TREADMILL_TRAVEL = 0.2
#: limb -> name pattern (case-insensitive, searched in a rigid body's or marker's name)
LIMB_PATTERNS = {
    "hat": r"hat|trunk|torso|thorax|pelvis|sacr|back|chest|c7|strn|stern|clav|neck|mid_?hip"
           r"|(^|[^a-z])(l|r|left|right)?[_\s:.\-]?(asis?|psis?)($|[^a-z])",
    "l_thigh": r"(^|[^a-z])(l|left)[_\s:.\-]?(thigh|thi|femur|hip|knee|kne)",
    "l_shank": r"(^|[^a-z])(l|left)[_\s:.\-]?(shank|tib|shin|leg|knee|kne|ankle|ank)",
    "l_foot": r"(^|[^a-z])(l|left)[_\s:.\-]?(foot|big_?toe|toe|heel|hee|mt|meta)",
    "r_thigh": r"(^|[^a-z])(r|right)[_\s:.\-]?(thigh|thi|femur|hip|knee|kne)",
    "p_shin": r"(^|[^a-z])(p|pros\w*|ampro\w*|r|right)[_\s:.\-]?(shin|shank|tib|leg|knee|kne"
              r"|ankle|ank)",
    "p_foot": r"(^|[^a-z])(p|pros\w*|ampro\w*|r|right)[_\s:.\-]?(foot|big_?toe|toe|heel|hee|mt"
              r"|meta)",
}
_HEEL, _TOE = re.compile(r"heel|hee|cal", re.I), re.compile(r"toe|mt|meta", re.I)
#: pelvis landmarks (Plug-in Gait's LASI/RASI/LPSI/RPSI/SACR, R.ASIS, V.Sacral): a lower-body
#: marker set has no trunk marker above them, so the pelvis's pitch stands in for the trunk's
#: (a posterior -> anterior pair along the hat's forward axis)
_PELVIS = re.compile(r"(^|[^a-z])(l|r|left|right)?[_\s:.\-]?(asis?|psis?|sacr\w*)($|[^a-z])",
                     re.I)
_ANTERIOR = re.compile(r"asis?($|[^a-z])", re.I)
_AXES = "xyz"


@dataclass(frozen=True)
class Column:
    """One marker or rigid body: valid share of the frames, longest gap (frames)."""

    name: str
    kind: str  # "marker", "rigid body", "rigid body marker"
    valid: float
    longest_gap: int


@dataclass(frozen=True)
class TakeSummary:
    source: str
    n_frames: int
    frame_rate: float
    duration: float  # s
    format_up: str
    columns: tuple[Column, ...]
    up_axis: str | None  # e.g. "+y": the file's, else the largest span with the format's sign
    up_span: float  # m, median per-frame span of the markers along it
    walk_axis: str | None  # e.g. "-x": the centroid's largest net travel
    walk_travel: float  # m
    up_reason: str = ""  # where up_axis comes from, for the user
    model_outputs: tuple[tuple[str, int], ...] = ()  # (kind, how many): not markers


def _longest_run(bad: np.ndarray) -> int:
    best = run = 0
    for b in bad:
        run = run + 1 if b else 0
        best = max(best, run)
    return best


def _column(name: str, kind: str, p: np.ndarray) -> Column:
    ok = np.all(np.isfinite(p), axis=1)
    return Column(name, kind, float(ok.mean()) if len(ok) else 0.0, _longest_run(~ok))


def _spans(take: Take) -> tuple[np.ndarray, np.ndarray] | None:
    """The markers' median per-frame span (3,) m and centroid (n, 3) m; None without any."""
    pts = [p for p in take.markers.values()] or [p for p in take.rigid_body_markers.values()]
    if not pts:
        return None
    P = np.stack(pts, axis=1)  # (n, m, 3)
    with warnings.catch_warnings():  # all-NaN frames
        warnings.simplefilter("ignore", RuntimeWarning)
        span = np.nanmedian(np.nanmax(P, axis=1) - np.nanmin(P, axis=1), axis=0)
        centroid = np.nanmean(P, axis=1)
    return (span, centroid) if np.isfinite(span).any() else None


def _up_guess(take: Take, span: np.ndarray) -> tuple[int, str, str]:
    """(lab axis index, axis string, why): the file's up axis if it gives one, else the
    largest span with the format's sign."""
    k = int(np.nanargmax(span))
    if take.up_axis_source:
        k_file = _AXES.index(take.up_axis[1])
        why = f"the file's {take.up_axis_source}"
        if k_file != k:
            why += f"; note: the markers span the most along {_AXES[k]}, check it"
        return k_file, take.up_axis, why
    default = take.up_axis
    sign = default[0] if default[1] == _AXES[k] else "+"
    return k, f"{sign}{_AXES[k]}", "the markers' largest span; sign from the format"


def summarize(take: Take) -> TakeSummary:
    """The take's columns, rate, length, model outputs and axis guesses (module
    docstring)."""
    cols = [_column(n, "marker", p) for n, p in take.markers.items()]
    cols += [_column(n, "rigid body", rb.position) for n, rb in take.rigid_bodies.items()]
    cols += [_column(n, "rigid body marker", p) for n, p in take.rigid_body_markers.items()]
    kinds: dict[str, int] = {}
    for o in take.model_outputs.values():
        kinds[o.kind] = kinds.get(o.kind, 0) + 1
    up_axis, up_span, walk_axis, walk, why = None, 0.0, None, 0.0, ""
    got = _spans(take)
    if got is not None:
        span, centroid = got
        k, up_axis, why = _up_guess(take, span)
        up_span = float(span[k])
        ok = np.all(np.isfinite(centroid), axis=1)
        if ok.sum() >= 2:
            d = centroid[ok][-1] - centroid[ok][0]
            d[k] = 0.0
            j = int(np.argmax(np.abs(d)))
            walk_axis = f"{'+' if d[j] >= 0 else '-'}{_AXES[j]}"
            walk = float(abs(d[j]))
    dur = float(take.time[-1] - take.time[0]) if take.n_frames else 0.0
    return TakeSummary(take.source, take.n_frames, take.frame_rate, dur, take.up_axis,
                       tuple(cols), up_axis, up_span, walk_axis, walk, why,
                       tuple(kinds.items()))


def _matches(limb: str, names: list[str]) -> list[str]:
    pat = re.compile(LIMB_PATTERNS[limb], re.I)
    return [n for n in names if pat.search(n)]


def _limb_guess(limb: str, take: Take) -> tuple[str | None, list[str]]:
    """(rigid body, markers) whose names look like the limb's."""
    rbs = _matches(limb, list(take.rigid_bodies))
    markers = _matches(limb, [*take.markers, *take.rigid_body_markers])
    rb = rbs[0] if rbs else None
    if rb is not None:  # prefer the rigid body's own markers
        own = [m for m in markers if m.split(":")[0] == rb]
        markers = own + [m for m in markers if m not in own]
    return rb, markers


def _distal_proximal(take: Take, names: list[str], up: str | None) -> list[str]:
    """Of a leg's or the trunk's markers, the lowest and the highest along the up guess (the
    longest pair, ordered distal -> proximal as the mapping wants it); the first two by name
    where heights are unknown."""
    if up is None or len(names) < 2:
        return names[:2]
    k, sign = _AXES.index(up[1]), (-1.0 if up[0] == "-" else 1.0)
    with warnings.catch_warnings():  # a marker lost in every frame
        warnings.simplefilter("ignore", RuntimeWarning)
        h = {n: sign * float(np.nanmedian(take.marker(n)[:, k])) for n in names}
    known = sorted((n for n in names if np.isfinite(h[n])), key=h.__getitem__)
    return [known[0], known[-1]] if len(known) >= 2 else names[:2]


def _pelvis_pair(names: list[str]) -> list[str] | None:
    """For a trunk known only by its pelvis landmarks: a posterior (PSIS or sacrum) and an
    anterior (ASIS) marker, of the same side where the names tell; None if the names are
    not all pelvis landmarks or either kind is missing."""
    if not names or not all(_PELVIS.search(n.split(":")[-1]) for n in names):
        return None
    front = [n for n in names if _ANTERIOR.search(n.split(":")[-1])]
    back = [n for n in names if n not in front]
    if not front or not back:
        return None
    same = [(b, f) for b in back for f in front if b[:1].lower() == f[:1].lower()]
    return list(same[0]) if same else [back[0], front[0]]


def _q(s: str) -> str:
    return '"' + s.replace("\\", "\\\\").replace('"', '\\"') + '"'


#: the model's leg limbs -> (side, proximal centre, distal centre) of :func:`_anatomical`
ANATOMICAL_LIMBS = {"l_thigh": ("l", "HJC", "KJC"), "l_shank": ("l", "KJC", "AJC"),
                    "r_thigh": ("r", "HJC", "KJC"), "p_shin": ("r", "KJC", "AJC")}


def _anatomical(take: Take) -> dict[str, list[str]] | None:
    """The virtual markers (name -> TOML value) that put the legs on their anatomical axes
    in every frame, when the take carries both epicondyles and malleoli of each leg and the
    pelvis's spines (:mod:`characterization.mocap.landmark_names`); None otherwise."""
    names = [*take.markers]
    legs, pelvis = leg_landmarks(names), pelvis_landmarks(names)
    if set(legs) != {"l", "r"} or pelvis is None:
        return None
    asis, back = pelvis
    out = {"HJC": [f"{{ asis = [{_q(asis[0])}, {_q(asis[1])}], sacrum = ["
                   + ", ".join(_q(b) for b in back) + "] }",
                   "the hip centre (Harrington et al. 2007) on the pelvis's midline"]}
    for side in ("l", "r"):
        lm = legs[side]
        out[f"{side.upper()}KJC"] = [f"[{_q(lm['knee_lat'])}, {_q(lm['knee_med'])}]",
                                     "the knee centre: the epicondyles' midpoint"]
        out[f"{side.upper()}AJC"] = [f"[{_q(lm['ankle_lat'])}, {_q(lm['ankle_med'])}]",
                                     "the ankle centre: the malleoli's midpoint"]
    if any(n in take.markers for n in out):
        return None
    return out


#: a trunk marker on the spine's 7th cervical vertebra (Plug-in Gait's, HBM2's, ISB's C7)
_C7 = re.compile(r"(^|[^a-z0-9])c7($|[^a-z0-9])", re.I)


def _spine(take: Take) -> tuple[dict[str, list[str]], list[str]] | None:
    """The trunk along the back, when the take has a C7 marker and the pelvis's posterior
    spines or sacrum: (the virtual marker it needs, name -> [TOML value, why]; the hat's
    pair, posterior pelvis -> C7).  A pair from an anterior pelvis marker to C7 leans the
    trunk by tens of degrees (gaitalytics' take: ASIS -> C7 read 21.5 deg off PSIS -> C7)."""
    names = [*take.markers]
    c7 = [n for n in names if _C7.search(n.split(":")[-1])]
    pelvis = pelvis_landmarks(names)
    if len(c7) != 1 or pelvis is None:
        return None
    back = pelvis[1]
    if len(back) == 1:
        return {}, [back[0], c7[0]]
    if "PSIS" in take.markers:
        return None
    return ({"PSIS": [f"[{_q(back[0])}, {_q(back[1])}]", "the posterior spines' midpoint"]},
            ["PSIS", c7[0]])


def _calibration(static: Take, static_path: str) -> list[str]:
    """The mapping's ``[calibration]`` for a static trial: its path, and its legs' landmarks
    and pelvis when it carries them all (the standing pitch of each leg segment)."""
    lines = ["[calibration]", f"static_trial = {_q(static_path)}"
             "   # standing in the neutral posture; relative to this file"]
    names = [*static.markers]
    legs, pelvis = leg_landmarks(names), pelvis_landmarks(names)
    if set(legs) != {"l", "r"} or pelvis is None:
        return [*lines, "# (no leg landmarks named in it: each limb taken as upright "
                "while standing)", ""]
    lines.append("# each leg segment's standing axis from the static trial's landmarks")
    for limb, (side, _, _) in ANATOMICAL_LIMBS.items():
        lm = legs[side]
        knee = f"[{_q(lm['knee_lat'])}, {_q(lm['knee_med'])}]"
        ankle = f"[{_q(lm['ankle_lat'])}, {_q(lm['ankle_med'])}]"
        lines.append(f"landmarks.{limb} = " + (f'["hip", {knee}]' if limb.endswith("thigh")
                                                 else f"[{knee}, {ankle}]"))
    asis, back = pelvis
    lines += [f"pelvis = {{ asis = [{_q(asis[0])}, {_q(asis[1])}], sacrum = ["
              + ", ".join(_q(b) for b in back) + "] }", ""]
    return lines


def _limb_entry(take: Take, limb: str, up_axis: str | None, anatomical: bool,
                trunk: list[str] | None) -> tuple[list[str], str]:
    """A limb's lines of the skeleton and its first (distal) marker; ``anatomical``: the
    leg segments on the virtual markers' centres (:func:`_anatomical`); ``trunk``: the
    hat's pair along the back (:func:`_spine`)."""
    if limb == "hat" and trunk is not None:
        return [f"[limbs.{limb}]", f"markers = [{_q(trunk[0])}, {_q(trunk[1])}]   # "
                "distal -> proximal along the back", ""], trunk[0]
    if anatomical and limb in ANATOMICAL_LIMBS:
        side, prox, dist = ANATOMICAL_LIMBS[limb]
        top = prox if prox == "HJC" else side.upper() + prox
        pair = [side.upper() + dist, top]
        return [f"[limbs.{limb}]", f"markers = [{_q(pair[0])}, {_q(pair[1])}]   # distal -> "
                "proximal centre (virtual markers)", ""], pair[0]
    rb, mk = _limb_guess(limb, take)
    foot = limb.endswith("foot")
    pelvis = _pelvis_pair(mk) if limb == "hat" else None
    pair = (mk[:2] if foot else pelvis if pelvis else _distal_proximal(take, mk, up_axis))
    if foot and len(mk) >= 2:
        heel = next((m for m in mk if _HEEL.search(m.split(":")[-1])), None)
        toe = next((m for m in mk if _TOE.search(m.split(":")[-1]) and m != heel), None)
        if heel and toe:
            pair = [heel, toe]
    lines = [f"[limbs.{limb}]"]
    if take.rigid_bodies:  # a take without any (C3D) is processed from the markers
        lines.append(f"rigid_body = {_q(rb) if rb else _q(TODO)}"
                     + ("" if rb else "   # or delete this line if the limb has none"))
    a, b = [*pair, TODO, TODO][:2]
    axis = ("heel -> toe" if foot else
            "posterior -> anterior (no trunk marker: the pelvis stands in)" if pelvis
            else "distal -> proximal")
    lines.append(f"markers = [{_q(a)}, {_q(b)}]   # {axis}")
    if foot:
        lines += ['pair_axis = "forward"', 'rigid_body_axis = "forward"']
    elif pelvis:
        lines.append('pair_axis = "forward"')
    lines.append("")
    return lines, (pair[0] if pair else TODO)


def mapping_skeleton(take: Take, static: Take | None = None, static_path: str = "") -> str:
    """A mapping TOML to edit (module docstring); with ``static`` (a static trial, at
    ``static_path`` relative to the mapping) its ``[calibration]``."""
    s = summarize(take)
    lines = [f"# mapping skeleton for {take.source} (hpcosim mocap inspect): check every",
             f"# entry; \"{TODO}\" marks what the names did not tell.  Format: README,",
             "# 'Mapping file'.  Columns in the take:"]
    for c in s.columns:
        lines.append(f"#   {c.kind:17s} {c.name}  ({100 * c.valid:.0f} % valid)")
    if s.model_outputs:
        lines.append("# and the lab's model outputs (not markers, not for the mapping): "
                     + ", ".join(f"{n} {k}" for k, n in s.model_outputs))
    lines += ["", "schema_version = 1",
              f"up = {_q(s.up_axis) if s.up_axis else _q('auto')}"
              f"        # {s.up_reason or 'guess'}: the body spans {s.up_span:.2f} m along it",
              'forward = "auto"   # the trunk\'s travel (or the feet on a treadmill)'
              + (f"; the markers travel {s.walk_travel:.2f} m along {s.walk_axis}"
                 if s.walk_axis and s.walk_travel >= TREADMILL_TRAVEL else
                 f"; the markers travel only {s.walk_travel:.2f} m: a treadmill?"
                 if s.walk_axis else ""), ""]
    legs, spine = _anatomical(take), _spine(take)
    virtual = {**(legs or {}), **(spine[0] if spine else {})}
    if virtual:
        lines += ["[virtual_markers]   # points built from the markers in every frame"
                  + ("; the legs' landmarks are on in walking: each leg segment on its "
                     "anatomical axis" if legs else "")]
        lines += [f"{name} = {value}   # {why}" for name, (value, why) in virtual.items()]
        lines.append("")
    first: dict[str, str] = {}
    for limb in LIMBS:
        entry, first[limb] = _limb_entry(take, limb, s.up_axis, legs is not None,
                                         spine[1] if spine else None)
        lines += entry
    for j, (a, b) in JOINTS.items():
        lines += [f"[joints.{j}]   # one marker on {a}, one on {b}",
                  f"markers = [{_q(first[a])}, {_q(first[b])}]", ""]
    lines += ["[segmentation]",
              f"human_foot_marker = {_q(first['l_foot'])}",
              f"prosthesis_foot_marker = {_q(first['p_foot'])}", "",
              "[processing]", "max_gap = 0.1", "lowpass_hz = 15.0", ""]
    if static is not None:
        lines += _calibration(static, static_path)
    return "\n".join(lines)
