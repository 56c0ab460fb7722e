"""OptiTrack Motive CSV exports: read and write (layout of Motive 1.2x-3.x, REFERENCE.md Sec. 4).

    Format Version,1.23,Take Name,t,...,Export Frame Rate,120,...,Rotation Type,Quaternion,
        Length Units,Meters,Coordinate Space,Global
    <blank line>
    ,Type,Rigid Body,...,Rigid Body Marker,...,Marker,...
    ,Name,Thigh,...,Thigh:Marker1,...,Unlabeled 1000,...
    ,ID,1,...
    ,,Rotation,Rotation,Rotation,Rotation,Position,Position,Position,Mean Marker Error,...
    Frame,Time (Seconds),X,Y,Z,W,X,Y,Z,,...
    0,0.000000,0.0123,...

Rotation Type is ``Quaternion`` (X, Y, Z, W: scalar last) or an Euler order such as ``XYZ``
(three columns in degrees, read as intrinsic rotations in that order).  Length Units:
Meters, Centimeters or Millimeters.  Empty cell = tracking lost.  Quality columns (Mean
Marker Error, Marker Quality) are optional.  Only ``Global`` coordinate space is accepted.
An export with timecode has a third column ``TimeCode`` (``Frame,Time (Seconds),TimeCode,
X,...``, values ``hh:mm:ss:ff``): it is dropped, its first value kept as the ``TimeCode
start`` metadata.
"""

from __future__ import annotations

import io
import os
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from characterization.mocap.take import MocapError, RigidBodyTrack, Take
from hp_model.atomic_io import atomic_write_text

LENGTH_UNITS = {"meters": 1.0, "centimeters": 0.01, "millimeters": 0.001}
EULER_ORDERS = ("XYZ", "XZY", "YXZ", "YZX", "ZXY", "ZYX")


_NAN = np.frombuffer(b"nan", dtype=np.uint8)


def _fill_empty(body: str) -> bytes:
    """``body`` as ASCII bytes with 'nan' in every empty cell after a comma (occluded
    markers): what the regex ``(?<=,)(?=,|$)`` (multiline) substitutes, as one numpy insert
    at the commas followed by a comma, a line end or the end (a quarter of the time of
    three ``str.replace`` passes on a 12 MB take).  Bytes, for ``np.loadtxt`` reads a
    bytes stream a third faster than a text one."""
    a = np.frombuffer(body.encode(), dtype=np.uint8)
    if a.size == 0:
        return b""
    after = np.empty_like(a)
    after[:-1] = a[1:]
    after[-1] = ord("\n")
    at = np.flatnonzero((a == ord(",")) & ((after == ord(",")) | (after == ord("\n")))) + 1
    if at.size == 0:
        return a.tobytes()
    return np.insert(a, np.repeat(at, 3), np.tile(_NAN, at.size)).tobytes()


#: frame times further apart than this many frame periods are a jump, not dropped frames
MAX_GAP_PERIODS = 10


def _metadata(first: str, src: str) -> dict[str, str]:
    cells = [c.strip() for c in first.split(",")]
    if len(cells) < 2 or cells[0] != "Format Version":
        raise MocapError(f"{src}: line 1: not a Motive CSV export (no 'Format Version' "
                         "metadata line)")
    return {cells[i]: cells[i + 1] for i in range(0, len(cells) - 1, 2) if cells[i]}


def _split_header(lines: list[str], src: str) -> tuple[dict[str, list[str]], int]:
    """Header rows by label (Type, Name, ID, quantity, axis) and the first data row index."""
    rows: dict[str, list[str]] = {}
    for i, line in enumerate(lines[1:12], start=1):
        cells = line.rstrip("\r").split(",")
        if not line.strip():
            continue
        label = cells[1].strip() if len(cells) > 1 else ""
        first = cells[0].strip()
        if first == "" and label in ("Type", "Name", "ID", "Parent"):
            rows[label] = cells
        elif first == "" and label == "":
            rows["quantity"] = cells
        elif first.lower() == "frame":
            rows["axis"] = cells
            return rows, i + 1
        else:
            break
    raise MocapError(f"{src}: no header rows (expected ',Type', ',Name' and 'Frame,Time' rows "
                     "before the data; export with header information switched on)")


@dataclass(frozen=True)
class _Columns:
    """How the metadata line says the columns are written: the length unit's scale to
    metres, the rotation type (``Quaternion`` or an Euler order) and the frame rate (Hz;
    NaN when not given)."""

    scale: float
    rot_type: str
    rate: float


def _columns(meta: dict[str, str], src: str) -> _Columns:
    """The checked length units, rotation type, coordinate space and frame rate."""
    units = meta.get("Length Units", "Meters")
    if units.lower() not in LENGTH_UNITS:
        raise MocapError(f"{src}: line 1, field 'Length Units': unknown units '{units}' "
                         f"(expected one of {', '.join(u.title() for u in LENGTH_UNITS)})")
    scale = LENGTH_UNITS[units.lower()]
    rot_type = meta.get("Rotation Type", "Quaternion")
    if rot_type != "Quaternion" and rot_type.upper() not in EULER_ORDERS:
        raise MocapError(f"{src}: line 1, field 'Rotation Type': unknown rotation type "
                         f"'{rot_type}' (expected Quaternion or an Euler order such as XYZ)")
    space = meta.get("Coordinate Space", "Global")
    if space != "Global":
        raise MocapError(f"{src}: line 1, field 'Coordinate Space': '{space}' is not supported "
                         "(export in Global coordinates)")
    rate_s = meta.get("Export Frame Rate") or meta.get("Capture Frame Rate")
    try:
        rate = float(rate_s) if rate_s else float("nan")
    except ValueError:
        raise MocapError(f"{src}: line 1, field 'Export Frame Rate': not a number "
                         f"'{rate_s}'") from None
    return _Columns(scale, rot_type, rate)


def _drop_timecode(rows: dict[str, list[str]], body: list[str], meta: dict[str, str]
                   ) -> tuple[dict[str, list[str]], list[str], dict[str, str]]:
    """Header rows, data lines and metadata without Motive's optional SMPTE TimeCode column
    (hh:mm:ss:ff), its first value kept as the metadata's ``TimeCode start``; unchanged
    when there is none."""
    tc = [j for j, c in enumerate(rows["axis"]) if c.strip().lower() == "timecode"]
    if not tc:
        return rows, body, meta
    j = tc[0]
    first = next((ln for ln in body if ln.strip()), "")
    cells = first.split(",")
    return ({k: r[:j] + r[j + 1:] for k, r in rows.items()}, [_drop_cell(ln, j) for ln in body],
            {**meta, "TimeCode start": cells[j].strip() if len(cells) > j else ""})


def _header_width(rows: dict[str, list[str]], src: str) -> int:
    """The number of columns, once the header rows needed are there and all that wide."""
    for need in ("Type", "Name", "quantity"):
        if need not in rows:
            raise MocapError(f"{src}: header row '{need}' missing")
    ncol = len(rows["axis"])
    for k, r in rows.items():
        if len(r) != ncol:
            raise MocapError(f"{src}: header row '{k}' has {len(r)} cells, the 'Frame' row "
                             f"has {ncol}")
    return ncol


def _frame_rate(time: np.ndarray, rate: float, data_start: int, src: str) -> float:
    """The frame rate (Hz): ``rate`` from the metadata, else from the median frame period;
    the frame times (s) checked present, increasing and without a jump (one take)."""
    if not np.all(np.isfinite(time)) or np.any(np.diff(time) <= 0):
        bad = int(np.argmax(~np.isfinite(time) | np.r_[False, np.diff(time) <= 0]))
        raise MocapError(f"{src}: column 'Time (Seconds)', data row {data_start + bad + 1}: "
                         "times must be present and increasing")
    if not np.isfinite(rate) or rate <= 0:
        rate = 1.0 / float(np.median(np.diff(time))) if len(time) > 1 else float("nan")
    if len(time) > 1:  # one continuous take: no jump in the frame times
        dt = np.diff(time)
        period = float(np.median(dt))
        jump = np.flatnonzero(dt > MAX_GAP_PERIODS * period)
        if jump.size:
            i = int(jump[0])
            raise MocapError(f"{src}: column 'Time (Seconds)', data rows {data_start + i + 1}-"
                             f"{data_start + i + 2}: the time jumps by {dt[i]:.3f} s "
                             f"({dt[i] / period:.0f} frame periods of {period * 1e3:.2f} ms): "
                             "not one continuous take (export one take per file)")
    return rate


#: the columns of one (Type, Name) by (quantity, axis)
_Group = dict[tuple[str, str], int]


def _column_groups(rows: dict[str, list[str]], ncol: int, src: str
                   ) -> dict[tuple[str, str], _Group]:
    """The data columns (from the third) grouped by (Type, Name), each by (quantity, axis)."""
    groups: dict[tuple[str, str], _Group] = {}
    for j in range(2, ncol):
        typ, name = rows["Type"][j].strip(), rows["Name"][j].strip()
        qty, axis = rows["quantity"][j].strip(), rows["axis"][j].strip()
        if not typ or not name:
            raise MocapError(f"{src}: column {j + 1}: empty Type or Name header cell")
        cols = groups.setdefault((typ, name), {})
        if (qty, axis) in cols:
            raise MocapError(f"{src}: column {j + 1}: duplicate column {typ} '{name}' "
                             f"{qty} {axis}")
        cols[(qty, axis)] = j
    return groups


def _take_cols(data: np.ndarray, src: str, typ: str, name: str, cols: _Group, qty: str,
               axes: Sequence[str]) -> np.ndarray:
    """The columns of ``qty`` along ``axes`` of one group, else a MocapError naming them."""
    try:
        return data[:, [cols[(qty, a)] for a in axes]]
    except KeyError:
        missing = [a for a in axes if (qty, a) not in cols]
        raise MocapError(f"{src}: {typ} '{name}': missing column {qty} "
                         f"{','.join(missing)}") from None


def _rigid_body(data: np.ndarray, src: str, name: str, cols: _Group, fmt: _Columns,
                data_start: int) -> RigidBodyTrack:
    """One rigid body's track (position in m, quaternion scalar last, lost where any
    rotation cell is; its mean marker error in m if exported); its quaternions checked of
    unit norm."""
    typ = "Rigid Body"
    pos = _take_cols(data, src, typ, name, cols, "Position", "XYZ") * fmt.scale
    if fmt.rot_type == "Quaternion":
        quat = _take_cols(data, src, typ, name, cols, "Rotation", "XYZW")
    else:
        eul = _take_cols(data, src, typ, name, cols, "Rotation", "XYZ")
        quat = _euler_to_quat(eul, fmt.rot_type.upper())
    lost = ~np.all(np.isfinite(quat), axis=1)
    quat[lost] = np.nan
    norms = np.linalg.norm(quat[~lost], axis=1)
    if np.any(np.abs(norms - 1.0) > 1e-3):
        bad = int(np.flatnonzero(~lost)[np.argmax(np.abs(norms - 1.0) > 1e-3)])
        raise MocapError(f"{src}: Rigid Body '{name}' Rotation, data row "
                         f"{data_start + bad + 1}: quaternion norm "
                         f"{np.linalg.norm(quat[bad]):.4f} is not 1")
    err = (data[:, cols[("Mean Marker Error", "")]] * fmt.scale
           if ("Mean Marker Error", "") in cols else None)
    return RigidBodyTrack(pos, quat, err)


def read_motive_csv(path: str | os.PathLike[str]) -> Take:
    """Read a Motive CSV export into a :class:`Take` (metres, lab axes, Y up)."""
    src = str(path)
    try:
        text = Path(path).read_text(encoding="utf-8-sig")
    except UnicodeDecodeError as e:
        raise MocapError(f"{src}: not a text file ({e.reason})") from None
    lines = text.splitlines()
    if not lines:
        raise MocapError(f"{src}: empty file")
    meta = _metadata(lines[0], src)
    fmt = _columns(meta, src)
    rows, data_start = _split_header(lines, src)
    rows, body, meta = _drop_timecode(rows, lines[data_start:], meta)
    ncol = _header_width(rows, src)
    data = _parse_data(body, ncol, data_start, src)
    if data.shape[0] == 0:
        raise MocapError(f"{src}: no data rows")
    time = data[:, 1]
    rate = _frame_rate(time, fmt.rate, data_start, src)
    markers: dict[str, np.ndarray] = {}
    rb_markers: dict[str, np.ndarray] = {}
    bodies: dict[str, RigidBodyTrack] = {}
    for (typ, name), cols in _column_groups(rows, ncol, src).items():
        if typ == "Rigid Body":
            bodies[name] = _rigid_body(data, src, name, cols, fmt, data_start)
        elif typ in ("Rigid Body Marker", "Marker"):
            into = rb_markers if typ == "Rigid Body Marker" else markers
            into[name] = _take_cols(data, src, typ, name, cols, "Position", "XYZ") * fmt.scale
        # other types (Bone, Force Plate, ...) are ignored
    for d in (markers, rb_markers):
        for v in d.values():
            v[~np.all(np.isfinite(v), axis=1)] = np.nan
    return Take(source=src, frame_rate=rate, time=time, markers=markers, rigid_bodies=bodies,
                rigid_body_markers=rb_markers, up_axis="+y", metadata=meta)


def _drop_cell(line: str, j: int) -> str:
    """``line`` without its comma-separated cell ``j`` (unchanged when it has none)."""
    cells = line.split(",")
    return ",".join(cells[:j] + cells[j + 1:]) if len(cells) > j else line


def _parse_data(lines: list[str], ncol: int, offset: int, src: str) -> np.ndarray:
    while lines and not lines[-1].strip():
        lines = lines[:-1]
    counts = np.fromiter((ln.count(",") for ln in lines), dtype=np.int64, count=len(lines))
    bad = np.flatnonzero(counts != ncol - 1)
    if bad.size:
        i = int(bad[0])
        frame = lines[i].split(",", 1)[0]
        raise MocapError(f"{src}: line {offset + i + 1} (frame {frame}): {counts[i] + 1} cells, "
                         f"expected {ncol} (truncated or damaged file)")
    if not lines:
        return np.zeros((0, ncol))
    body = _fill_empty("\n".join(ln.rstrip("\r") for ln in lines))
    try:
        return np.loadtxt(io.BytesIO(body), delimiter=",", ndmin=2)
    except ValueError:
        for i, ln in enumerate(lines):
            for j, cell in enumerate(ln.split(",")):
                try:
                    float(cell) if cell.strip() else None
                except ValueError:
                    raise MocapError(f"{src}: line {offset + i + 1} (frame "
                                     f"{ln.split(',', 1)[0]}), column {j + 1}: not a number "
                                     f"'{cell.strip()[:20]}'") from None
        raise


def _euler_to_quat(eul_deg: np.ndarray, order: str) -> np.ndarray:
    from scipy.spatial.transform import Rotation  # only for Euler exports

    out = np.full((eul_deg.shape[0], 4), np.nan)
    ok = np.all(np.isfinite(eul_deg), axis=1)
    if ok.any():
        # Motive writes the angles in the X, Y, Z columns; the order says how they compose
        ang = np.stack([eul_deg[ok, "XYZ".index(c)] for c in order], axis=1)
        out[ok] = Rotation.from_euler(order, ang, degrees=True).as_quat()
    return out


def _quat_to_euler(quat: np.ndarray, order: str) -> np.ndarray:
    from scipy.spatial.transform import Rotation  # only for Euler exports

    out = np.full((quat.shape[0], 3), np.nan)
    ok = np.all(np.isfinite(quat), axis=1)
    if ok.any():
        ang = Rotation.from_quat(quat[ok]).as_euler(order, degrees=True)
        for k, c in enumerate(order):
            out[ok, "XYZ".index(c)] = ang[:, k]
    return out


def write_motive_csv(path: str | os.PathLike[str], take: Take, *, units: str = "Meters",
                     rotation_type: str = "Quaternion", take_name: str = "synthetic",
                     decimals: int = 6) -> None:
    """Write a take in Motive's CSV layout (atomically: temp file + rename)."""
    scale = LENGTH_UNITS[units.lower()]
    header_type, header_name, header_id, header_qty, header_axis = [], [], [], [], []
    cols: list[np.ndarray] = []
    ident = 1

    def add(typ: str, name: str, qty: str, axes: str, arr: np.ndarray) -> None:
        for k, a in enumerate(axes or " "):
            header_type.append(typ)
            header_name.append(name)
            header_id.append(str(ident))
            header_qty.append(qty)
            header_axis.append(a.strip())
            cols.append(arr[:, k] if arr.ndim == 2 else arr)

    for name, rb in take.rigid_bodies.items():
        if rotation_type == "Quaternion":
            add("Rigid Body", name, "Rotation", "XYZW", rb.quaternion)
        else:
            add("Rigid Body", name, "Rotation", "XYZ", _quat_to_euler(rb.quaternion,
                                                                       rotation_type))
        add("Rigid Body", name, "Position", "XYZ", rb.position / scale)
        if rb.mean_error is not None:
            add("Rigid Body", name, "Mean Marker Error", "", rb.mean_error / scale)
        ident += 1
    for name, p in take.rigid_body_markers.items():
        add("Rigid Body Marker", name, "Position", "XYZ", p / scale)
        add("Rigid Body Marker", name, "Marker Quality", "",
            np.where(np.isfinite(p[:, 0]), 1.0, np.nan))
        ident += 1
    for name, p in take.markers.items():
        add("Marker", name, "Position", "XYZ", p / scale)
        ident += 1

    n = take.n_frames
    meta = (f"Format Version,1.23,Take Name,{take_name},Capture Frame Rate,"
            f"{take.frame_rate:.6f},Export Frame Rate,{take.frame_rate:.6f},Total Frames in "
            f"Take,{n},Total Exported Frames,{n},Rotation Type,{rotation_type},Length Units,"
            f"{units},Coordinate Space,Global")
    buf = io.StringIO()
    buf.write(meta + "\n\n")
    buf.write(",Type," + ",".join(header_type) + "\n")
    buf.write(",Name," + ",".join(header_name) + "\n")
    buf.write(",ID," + ",".join(header_id) + "\n")
    buf.write(",," + ",".join(header_qty) + "\n")
    buf.write("Frame,Time (Seconds)," + ",".join(header_axis) + "\n")
    table = np.column_stack([np.arange(n), take.time, *cols]) if cols else \
        np.column_stack([np.arange(n), take.time])
    fmt = f"%.{decimals}f"
    body = io.StringIO()
    np.savetxt(body, table, delimiter=",", fmt=["%d", "%.6f"] + [fmt] * len(cols))
    buf.write(body.getvalue().replace("nan", ""))
    atomic_write_text(path, buf.getvalue())
