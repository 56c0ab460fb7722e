"""A strict JSON parser (as JavaScript's ``JSON.parse``: no ``NaN``, ``Infinity``,
``-Infinity``) for the tests of what hpcosim writes."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any


def _refuse(name: str) -> Any:
    raise ValueError(f"{name} is not JSON")


def strict_loads(text: str) -> Any:
    """``json.loads`` that refuses NaN and +-Infinity."""
    return json.loads(text, parse_constant=_refuse)


def assert_strict_json_files(folder: Path) -> list[Path]:
    """Every ``*.json`` under ``folder`` parses strictly; returns them (sorted)."""
    files = sorted(folder.rglob("*.json"))
    for f in files:
        try:
            strict_loads(f.read_text())
        except ValueError as e:
            raise AssertionError(f"{f}: {e}") from None
    return files
