"""The one JSON encoder of everything hpcosim writes as JSON: the artifacts (gait, tube, steps
as ``.json``), the QA summary, metrics.json, the sweep's manifest and report, the FMU's
build_info.json, the controller node's summary line.

The rule (JSON has no NaN or infinity, and hpcosim writes neither):

- a non-finite float (NaN, +inf, -inf; Python or numpy, alone or in an array) is ``null``;
- numpy arrays become (nested) lists, numpy scalars Python numbers, mappings objects with
  string keys (a ``StrEnum`` key is its word), tuples arrays;
- the text is made with ``allow_nan=False``, so a non-finite value that escaped the
  conversion is a ``ValueError``, never ``NaN`` or ``Infinity`` text that a strict parser
  (JavaScript's ``JSON.parse``) refuses; a type JSON has no form for is a ``TypeError``.

``null`` therefore means "no finite value".  Where a reader must tell +inf from missing,
the artifact's format doc says what ``null`` stands for and the reader maps it back: the
gait's ``options`` (``hp_model.gait_artifact``), where ``null`` is a bound that is off
(+inf, e.g. ``touchdown_slip``; read by ``hp_model.artifacts.FieldReader.settings``).

The MCAP recorder's JSON messages are the one exception in code, not in rule: its
``encode_json`` (``bus_schemas``) uses orjson, about 5x faster than this module on its
per-tick records, and orjson writes NaN and +-inf as ``null`` too.
"""

from __future__ import annotations

import json
import math
import os
from collections.abc import Mapping
from typing import Any

import numpy as np

from hp_model.atomic_io import atomic_write_text


def finite_or_none(x: float | None) -> float | None:
    """``float(x)`` if finite, else None (a missing or non-finite number)."""
    return float(x) if x is not None and math.isfinite(float(x)) else None


def to_jsonable(v: Any) -> Any:
    """``v`` as plain JSON data by the module's rule (non-finite floats to None, numpy to
    lists and numbers, mappings to dicts with string keys, tuples to lists), recursively."""
    if isinstance(v, float):  # np.float64 included
        return float(v) if math.isfinite(v) else None
    if isinstance(v, np.ndarray):
        if v.dtype.kind == "f" and not np.all(np.isfinite(v)):
            out = v.astype(object)
            out[~np.isfinite(v)] = None
            return out.tolist()
        return to_jsonable(v.tolist()) if v.dtype.kind == "O" else v.tolist()
    if isinstance(v, np.generic):
        return to_jsonable(v.item())
    if isinstance(v, Mapping):
        return {str(k): to_jsonable(x) for k, x in v.items()}
    if isinstance(v, list | tuple):
        return [to_jsonable(x) for x in v]
    return v


def dumps(obj: Any, *, indent: int | None = None, sort_keys: bool = False,
          separators: tuple[str, str] | None = None) -> str:
    """The JSON text of ``obj`` by the module's rule (arguments as ``json.dumps``)."""
    return json.dumps(to_jsonable(obj), allow_nan=False, indent=indent, sort_keys=sort_keys,
                      separators=separators)


def write_json(path: str | os.PathLike[str], obj: Any, *, indent: int | None = 1) -> None:
    """Write :func:`dumps` of ``obj`` and a newline to ``path`` atomically."""
    atomic_write_text(path, dumps(obj, indent=indent) + "\n")
