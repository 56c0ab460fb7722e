"""Compact JSON of a record (:func:`encode_json`): numpy values become lists and numbers,
NaN and inf become null (JSON has no NaN), what orjson cannot encode goes through the
json module: the same JSON values either way."""

from __future__ import annotations

import base64
import json
import math
from collections.abc import Mapping
from typing import Any

import orjson


def _default(o: Any) -> Any:
    """numpy scalars and arrays, enums, bytes -> JSON values."""
    if hasattr(o, "tolist"):
        return o.tolist()
    if hasattr(o, "item"):
        return o.item()
    if isinstance(o, bytes | bytearray):
        return base64.b64encode(o).decode()
    if isinstance(o, set | frozenset | tuple):
        return list(o)
    raise TypeError(f"{type(o).__name__} is not JSON serializable")


def _finite(o: Any) -> Any:
    if isinstance(o, float):
        return o if math.isfinite(o) else None
    if isinstance(o, Mapping):
        return {k: _finite(v) for k, v in o.items()}
    if isinstance(o, list | tuple):
        return [_finite(v) for v in o]
    return o


_ORJSON_OPTIONS = orjson.OPT_SERIALIZE_NUMPY | orjson.OPT_NON_STR_KEYS


def encode_json(obj: Any) -> bytes:
    """Compact JSON of ``obj``; numpy values become lists/numbers, NaN/inf become null.

    orjson (about 5x faster than the json module on these records) writes the same JSON
    values; what it cannot encode (integers beyond 64 bits) goes through the json module.
    """
    try:
        return orjson.dumps(obj, default=_default, option=_ORJSON_OPTIONS)
    except (orjson.JSONEncodeError, TypeError):
        pass
    try:
        return json.dumps(obj, separators=(",", ":"), allow_nan=False,
                          default=_default).encode()
    except ValueError:
        plain = json.loads(json.dumps(obj, default=_default))  # NaN -> float('nan')
        return json.dumps(_finite(plain), separators=(",", ":"), allow_nan=False).encode()
