"""Anatomical landmarks recognized by their markers' names, for ``mocap inspect``'s mapping
skeleton: both femoral epicondyles and both malleoli of each leg, and the pelvis's spines
(:func:`leg_landmarks`, :func:`pelvis_landmarks`).  A walking take that carries them all
gets virtual markers (the legs' anatomical axes in every frame), a static trial that does
gets calibration landmarks (docs/cli.md "Mapping file").

Names are matched by their stem: the side prefix (``L``/``R``/``Left``/``Right``, with or
without a separator) and separators removed, lower case.  The stems are those of Plug-in
Gait (LKNE, LANK, LMMA, LASI, LPSI, SACR), HBM2 (LLEK, LMEK, LLM, LMM, LASIS, LPSIS),
ISB-style (LFLE, LFME, LFAL, LTAM) and OpenSim's examples (L.Knee.Lat, L.Ankle.Med,
L.ASIS, V.Sacral).  A landmark is proposed only when exactly one marker of the side has its
stem.
"""

from __future__ import annotations

import re
from collections.abc import Iterable

#: landmark -> the stems that name it
LEG_STEMS: dict[str, frozenset[str]] = {
    "knee_lat": frozenset({"kne", "knee", "lek", "lfe", "fle", "kneelat", "kneelateral",
                           "latknee", "lfepi", "latepi", "knl", "knel"}),
    "knee_med": frozenset({"knm", "knem", "mek", "mfe", "fme", "kneemed", "kneemedial",
                           "medknee", "mfepi", "medepi", "kmed"}),
    "ankle_lat": frozenset({"ank", "ankle", "lm", "lmal", "fal", "anklat", "anklelat",
                            "anklelateral", "latankle", "latmal"}),
    "ankle_med": frozenset({"mma", "mm", "mmal", "tam", "ankmed", "anklemed",
                            "anklemedial", "medankle", "medmal"}),
}
_ASIS, _PSIS = frozenset({"asi", "asis"}), frozenset({"psi", "psis"})
_SEPARATORS = re.compile(r"[_\s:.\-]")


def side_and_stem(name: str) -> tuple[str | None, str]:
    """("l" | "r" | None, the stem) of a marker's name (its last ``:``-part)."""
    base = name.split(":")[-1]
    m = re.match(r"(left|right)[_\s.\-]?(.+)$", base, re.I) or re.match(
        r"([LR])[_\s.\-]?(.+)$", base)
    if m is None:
        return None, _SEPARATORS.sub("", base).lower()
    return m.group(1)[0].lower(), _SEPARATORS.sub("", m.group(2)).lower()


def leg_landmarks(names: Iterable[str]) -> dict[str, dict[str, str]]:
    """side ("l", "r") -> {landmark: marker} for each side whose four leg landmarks are
    each named by exactly one marker."""
    found: dict[str, dict[str, list[str]]] = {"l": {}, "r": {}}
    for n in names:
        side, stem = side_and_stem(n)
        if side is None:
            continue
        for landmark, stems in LEG_STEMS.items():
            if stem in stems:
                found[side].setdefault(landmark, []).append(n)
    return {side: {k: v[0] for k, v in got.items()}
            for side, got in found.items()
            if set(got) == set(LEG_STEMS) and all(len(v) == 1 for v in got.values())}


def pelvis_landmarks(names: Iterable[str]) -> tuple[list[str], list[str]] | None:
    """(the two ASIS, the sacrum: a sacral marker or both PSIS) named in ``names``, or None."""
    asis: dict[str, str] = {}
    psis: dict[str, str] = {}
    sacrum: list[str] = []
    for n in names:
        side, stem = side_and_stem(n)
        if side is not None and stem in _ASIS:
            asis[side] = n
        elif side is not None and stem in _PSIS:
            psis[side] = n
        elif "sacr" in _SEPARATORS.sub("", n.split(":")[-1]).lower():
            sacrum.append(n)
    if set(asis) != {"l", "r"}:
        return None
    back = [psis["l"], psis["r"]] if set(psis) == {"l", "r"} else sacrum[:1]
    return ([asis["l"], asis["r"]], back) if back else None
