"""Shared plumbing of the versioned JSON artifacts (gait, tube): canonical hashing, one-line
validation errors naming the file and the field, atomic saving (through the one JSON
encoder, :mod:`hp_model.json_io`: a non-finite number is written as ``null``)."""

from __future__ import annotations

import hashlib
import json
import math
import os
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from hp_model.json_io import dumps, to_jsonable, write_json


class ArtifactError(ValueError):
    """A gait or tube file is unreadable, of another version, or has a bad field."""


def canonical_hash(obj: Any) -> str:
    """sha256 (hex, 16 chars) of the canonical JSON of ``obj`` (sorted keys, rounded floats
    so that a save/load round trip keeps the hash)."""
    def rnd(v: Any) -> Any:
        if isinstance(v, float):
            return float(f"{v:.12g}")
        if isinstance(v, dict):
            return {k: rnd(x) for k, x in v.items()}
        if isinstance(v, list):
            return [rnd(x) for x in v]
        return v

    text = dumps(rnd(to_jsonable(obj)), sort_keys=True, separators=(",", ":"))
    return hashlib.sha256(text.encode()).hexdigest()[:16]


def save_json(path: str | os.PathLike[str], doc: Mapping[str, Any]) -> None:
    """Write the document atomically (temp file + rename)."""
    write_json(path, doc, indent=1)


def load_json(path: str | os.PathLike[str], kind: str, version: int | tuple[int, ...]
              ) -> dict[str, Any]:
    """Read a JSON artifact of the given ``kind`` and schema ``version`` (or one of the
    versions given as a tuple)."""
    p = Path(path)
    if not p.is_file():
        raise FileNotFoundError(f"{p}: no such file")
    try:
        doc = json.loads(p.read_text())
    except (UnicodeDecodeError, json.JSONDecodeError) as e:
        raise ArtifactError(f"{p}: not a {kind} file ({type(e).__name__})") from None
    if not isinstance(doc, dict) or doc.get("kind") != kind:
        raise ArtifactError(f"{p}: not a {kind} file (field 'kind' is not '{kind}')")
    ver = doc.get("schema_version")
    versions = version if isinstance(version, tuple) else (version,)
    if isinstance(ver, bool) or ver not in versions:
        raise ArtifactError(f"{p}: field 'schema_version': version {ver} is not supported "
                            f"(this program reads {', '.join(map(str, versions))})")
    return doc


class FieldReader:
    """Typed access to a loaded document; every failure names the file and the field."""

    def __init__(self, src: str, doc: Mapping[str, Any]) -> None:
        self.src, self.doc = src, doc

    def fail(self, field: str, what: str) -> ArtifactError:
        return ArtifactError(f"{self.src}: field '{field}': {what}")

    def get(self, field: str) -> Any:
        cur: Any = self.doc
        for part in field.split("."):
            if not isinstance(cur, Mapping) or part not in cur:
                raise self.fail(field, "missing")
            cur = cur[part]
        return cur

    def array(self, field: str, shape: tuple[int | None, ...] | None = None) -> np.ndarray:
        try:
            a = np.asarray(self.get(field), dtype=float)
        except (TypeError, ValueError):
            raise self.fail(field, "not a numeric array") from None
        if shape is not None and (a.ndim != len(shape) or any(
                s is not None and s != n for s, n in zip(shape, a.shape, strict=True))):
            want = "x".join("n" if s is None else str(s) for s in shape)
            raise self.fail(field, f"shape {a.shape}, expected ({want})")
        if not np.all(np.isfinite(a)):
            raise self.fail(field, "non-finite values")
        a.setflags(write=False)
        return a

    def number(self, field: str, lo: float = -np.inf, hi: float = np.inf) -> float:
        v = self.get(field)
        if isinstance(v, bool) or not isinstance(v, int | float) or not np.isfinite(v):
            raise self.fail(field, "not a finite number")
        if not lo <= v <= hi:
            raise self.fail(field, f"{v} outside [{lo}, {hi}]")
        return float(v)

    def settings(self, field: str) -> dict[str, Any]:
        """An object of settings as written (numbers, strings, lists), each ``null`` read as
        +inf: a bound that is off (a non-finite number is written as null,
        :mod:`hp_model.json_io`)."""
        v = self.get(field)
        if not isinstance(v, Mapping):
            raise self.fail(field, "not an object")
        return {str(k): math.inf if x is None else x for k, x in v.items()}

    def string(self, field: str) -> str:
        v = self.get(field)
        if not isinstance(v, str):
            raise self.fail(field, "not a string")
        return v
