"""Tables as the tools labs use read them: CSV with a header row naming each column's unit,
and OpenSim's motion / storage files (``.mot``, ``.sto``); both written atomically.

CSV: one header row, ``name [unit]`` per column (a column without a unit, such as the
domain's word, is its name alone), then one row per sample; numbers as Python's shortest
round-trip repr (``float(text)`` gives the value back bit for bit), a missing value empty.

OpenSim (the header of its own IK output; opensim-core ``DelimFileAdapter``; OpenSim
documentation, "Motion (.mot) Files" and "Storage (.sto) Files")::

    <name>                      the table's name
    version=1
    nRows=<N>                   data rows
    nColumns=<M>                columns, the time column included
    inDegrees=yes|no            whether the rotational values are in degrees
    <comment lines>             free text (no '='; OpenSim keeps it as the header)
    endheader
    time<TAB><label>...         the column labels, ``time`` first
    <N rows of M tab-separated numbers>

OpenSim refuses a time that does not increase strictly (``TimestampLessThanEqualToPrevious``),
so :func:`mot_text` does too.
"""

from __future__ import annotations

import csv
import io
import math
import os
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from hp_model.atomic_io import atomic_write_text

#: what OpenSim's header says of the units (its IK output's wording)
SI_UNITS = "Units are S.I. units (second, meters, Newtons, ...)"


class TableError(ValueError):
    """A table that cannot be written as asked (one line)."""


@dataclass(frozen=True)
class Column:
    """One column: its name, its unit (``None``: no unit, e.g. a word or a count) and its
    values (numbers, ``None`` or NaN where missing; or words)."""

    name: str
    unit: str | None
    values: Sequence[float | int | str | None] | np.ndarray

    @property
    def header(self) -> str:
        return f"{self.name} [{self.unit}]" if self.unit else self.name


def number_text(v: float | int | str | None) -> str:
    """A cell: a number as its shortest round-trip repr, a word as it is, missing empty."""
    if v is None:
        return ""
    if isinstance(v, str):
        return v
    if isinstance(v, (bool, np.bool_)):
        return str(int(v))
    if isinstance(v, (int, np.integer)):
        return str(int(v))
    x = float(v)
    return "" if math.isnan(x) else repr(x)


def csv_text(columns: Sequence[Column]) -> str:
    """The CSV text of ``columns`` (all of one length): the header row, then the rows."""
    n = {len(c.values) for c in columns}
    if len(n) != 1:
        raise TableError("columns of different lengths: "
                         + ", ".join(f"{c.name} {len(c.values)}" for c in columns))
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow([c.header for c in columns])
    for row in zip(*(c.values for c in columns), strict=True):
        w.writerow([number_text(v) for v in row])
    return buf.getvalue()


def write_csv(path: str | os.PathLike[str], columns: Sequence[Column]) -> None:
    """Write ``columns`` as a CSV file, atomically."""
    atomic_write_text(path, csv_text(columns))


@dataclass(frozen=True)
class MotTable:
    """An OpenSim motion table: ``time`` (N,) strictly increasing, s; ``data`` (N, M-1) in
    the order of ``labels``; ``in_degrees``: the rotational columns are in degrees;
    ``comments``: header lines (no '=')."""

    name: str
    time: np.ndarray
    labels: tuple[str, ...]
    data: np.ndarray
    in_degrees: bool
    comments: tuple[str, ...] = (SI_UNITS,)


def _check(table: MotTable) -> None:
    t, data = np.asarray(table.time, float), np.asarray(table.data, float)
    if data.ndim != 2 or data.shape != (t.size, len(table.labels)):
        raise TableError(f"{table.name}: data {data.shape} for {t.size} times and "
                         f"{len(table.labels)} labels")
    if len(set(table.labels)) != len(table.labels) or "time" in table.labels:
        raise TableError(f"{table.name}: column labels must be unique and not 'time'")
    for label in (table.name, *table.labels):
        if not label or "=" in label or any(ch.isspace() for ch in label):
            raise TableError(f"{label!r}: a name or label with a blank or '='")
    if any("=" in c or c.strip() == "endheader" for c in table.comments):
        raise TableError(f"{table.name}: a header comment with '=' or 'endheader'")
    if t.size and not np.all(np.diff(t) > 0):
        k = int(np.argmax(np.diff(t) <= 0)) + 1
        raise TableError(f"{table.name}: time does not increase at row {k} "
                         f"({t[k - 1]!r} then {t[k]!r}); OpenSim refuses it")


def mot_text(table: MotTable) -> str:
    """The text of an OpenSim ``.mot`` / ``.sto`` file (module docstring)."""
    _check(table)
    t, data = np.asarray(table.time, float), np.asarray(table.data, float)
    lines = [table.name, "version=1", f"nRows={t.size}",
             f"nColumns={len(table.labels) + 1}",
             f"inDegrees={'yes' if table.in_degrees else 'no'}", *table.comments,
             "endheader", "\t".join(("time", *table.labels))]
    for k in range(t.size):
        lines.append("\t".join(_mot_number(x) for x in (t[k], *data[k])))
    return "\n".join(lines) + "\n"


def _mot_number(x: float) -> str:
    return "NaN" if math.isnan(x) else repr(float(x))


def write_mot(path: str | os.PathLike[str], table: MotTable) -> None:
    """Write an OpenSim motion file, atomically."""
    atomic_write_text(path, mot_text(table))
