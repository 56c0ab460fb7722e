"""TRC marker files (OpenSim's format, tab separated): read and write.

    PathFileType  4  (X/Y/Z)  walk.trc
    DataRate  CameraRate  NumFrames  NumMarkers  Units  OrigDataRate  OrigDataStartFrame  ...
    120  120  885  28  mm  120  1  885
    Frame#  Time  LASI  <tab>  <tab>  RASI ...
            X1  Y1  Z1  X2  Y2  Z2 ...
    <blank line>
    1  0.000000  12.3  ...

Units: ``mm``, ``cm`` or ``m``.  An empty cell (or NaN) is a lost sample.  OpenSim's lab
frame has Y up, so the format's default up axis is ``+y`` (the mocap checks infer it from
the data anyway).  Every error is one line naming the file, the line and what is wrong.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from characterization.mocap.motive_csv import MAX_GAP_PERIODS
from characterization.mocap.take import MocapError, Take
from hp_model.atomic_io import atomic_write_text

UNITS = {"mm": 1e-3, "cm": 1e-2, "m": 1.0}


def read_trc(path: str | os.PathLike[str]) -> Take:
    """A :class:`Take` (markers only) from a TRC file."""
    src = str(path)
    try:
        lines = Path(path).read_text().splitlines()
    except UnicodeDecodeError:
        raise MocapError(f"{src}: not a text file (TRC expected)") from None
    if not lines or not lines[0].startswith("PathFileType"):
        raise MocapError(f"{src}: line 1: not a TRC file (no 'PathFileType' header)")
    if len(lines) < 5:
        raise MocapError(f"{src}: the header is cut short ({len(lines)} lines, 5 expected)")
    rate, n_markers, units = _data_header(lines[1], lines[2], src)
    names = _marker_names(lines[3], n_markers, src)
    data = _data_rows(lines, 2 + 3 * n_markers, src)
    time = data[:, 1]
    _check_time(time, rate, src)
    s = UNITS[units.lower()]
    markers = {n: data[:, 2 + 3 * j:5 + 3 * j] * s for j, n in enumerate(names)}
    return Take(source=src, frame_rate=rate, time=time, markers=markers, up_axis="+y",
                metadata={"format": "trc", "Units": units})


def _data_header(keys_line: str, values_line: str, src: str) -> tuple[float, int, str]:
    """(DataRate (Hz), NumMarkers, Units as written) of the header's lines 2 and 3."""
    keys = [k.strip() for k in keys_line.split("\t")]
    vals = [v.strip() for v in values_line.split("\t")]
    meta = dict(zip(keys, vals, strict=False))
    for key in ("DataRate", "NumMarkers", "Units"):
        if not meta.get(key):
            raise MocapError(f"{src}: line 3: no value for '{key}'")
    try:
        rate, n_markers = float(meta["DataRate"]), int(float(meta["NumMarkers"]))
    except ValueError:
        raise MocapError(f"{src}: line 3: DataRate '{meta['DataRate']}' or NumMarkers "
                         f"'{meta['NumMarkers']}' is not a number") from None
    if meta["Units"].lower() not in UNITS:
        raise MocapError(f"{src}: line 3: unknown Units '{meta['Units']}' (expected "
                         f"{', '.join(UNITS)})")
    if not rate > 0 or n_markers < 1:
        raise MocapError(f"{src}: line 3: DataRate must be > 0 and NumMarkers >= 1")
    return rate, n_markers, meta["Units"]


def _marker_names(names_line: str, n_markers: int, src: str) -> list[str]:
    """The ``n_markers`` marker names of the header's line 4 (every third cell from the
    third), checked present and distinct."""
    names = [c.strip() for c in names_line.split("\t")[2::3]][:n_markers]
    if len(names) < n_markers or not all(names):
        raise MocapError(f"{src}: line 4: {len([n for n in names if n])} marker names for "
                         f"NumMarkers {n_markers}")
    if len(set(names)) != len(names):
        dup = next(n for n in names if names.count(n) > 1)
        raise MocapError(f"{src}: line 4: duplicate marker name '{dup}'")
    return names


def _data_rows(lines: list[str], ncol: int, src: str) -> np.ndarray:
    """The data rows after the header's 5 lines as an (n, ncol) array (Frame#, Time, then
    X, Y, Z per marker; an empty cell is NaN); blank lines skipped."""
    rows = []
    for i, line in enumerate(lines[5:], start=6):
        if not line.strip():
            continue
        c = line.split("\t")
        if len(c) > ncol and any(x.strip() for x in c[ncol:]):
            raise MocapError(f"{src}: line {i}: {len(c)} cells, expected {ncol}")
        c = (c + [""] * ncol)[:ncol]
        try:
            rows.append([float(x) if x.strip() else np.nan for x in c])
        except ValueError:
            bad = next(x for x in c if x.strip() and not _is_number(x))
            raise MocapError(f"{src}: line {i}: not a number '{bad.strip()[:20]}'") from None
    if not rows:
        raise MocapError(f"{src}: no frames")
    return np.asarray(rows)


def _check_time(time: np.ndarray, rate: float, src: str) -> None:
    """The frame times (s) present, increasing and without a jump (one continuous take)."""
    if not np.all(np.isfinite(time)):
        k = int(np.flatnonzero(~np.isfinite(time))[0])
        raise MocapError(f"{src}: data row {k + 1}: no time")
    dt = np.diff(time)
    if np.any(dt <= 0):
        k = int(np.flatnonzero(dt <= 0)[0])
        raise MocapError(f"{src}: data rows {k + 1}-{k + 2}: the time does not increase")
    if dt.size and np.any(dt > MAX_GAP_PERIODS / rate):
        k = int(np.flatnonzero(dt > MAX_GAP_PERIODS / rate)[0])
        raise MocapError(f"{src}: data rows {k + 1}-{k + 2}: the time jumps by {dt[k]:.3f} s "
                         f"({dt[k] * rate:.0f} frame periods): not one continuous take")


def _is_number(x: str) -> bool:
    try:
        float(x)
    except ValueError:
        return False
    return True


def write_trc(path: str | os.PathLike[str], take: Take, *, units: str = "mm") -> None:
    """Write the take's reconstructed markers to a TRC file (atomically)."""
    s = UNITS[units]
    names = list(take.markers)
    n = take.n_frames
    head = [f"PathFileType\t4\t(X/Y/Z)\t{Path(path).name}",
            "DataRate\tCameraRate\tNumFrames\tNumMarkers\tUnits\tOrigDataRate\t"
            "OrigDataStartFrame\tOrigNumFrames",
            f"{take.frame_rate:g}\t{take.frame_rate:g}\t{n}\t{len(names)}\t{units}\t"
            f"{take.frame_rate:g}\t1\t{n}",
            "Frame#\tTime\t" + "\t".join(f"{m}\t\t" for m in names).rstrip("\t"),
            "\t\t" + "\t".join(f"X{k + 1}\tY{k + 1}\tZ{k + 1}" for k in range(len(names))),
            ""]
    body = []
    for i in range(n):
        vals = []
        for m in names:
            p = take.markers[m][i] / s
            vals += ["" if not np.isfinite(v) else f"{v:.6f}" for v in p]
        body.append(f"{i + 1}\t{take.time[i]:.6f}\t" + "\t".join(vals))
    atomic_write_text(path, "\n".join(head + body) + "\n")
