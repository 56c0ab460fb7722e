"""String choices as enums: :class:`Choice`, the base of every mode, status and kind that
configs, command lines and files spell as a word.

A member is its string (``StrEnum``): it compares equal to it, formats and serializes as it
(JSON, TOML, MCAP, f-strings), so files keep their format.  Parsing anything else raises a
one-line ``ValueError`` naming the choices: ``CompileBackend("gcc")`` raises "unknown compile
backend 'gcc'; choose one of auto, c, sx".
"""

from __future__ import annotations

import re
from enum import StrEnum
from typing import Any


class Choice(StrEnum):
    """A closed set of words; ``Choice(value)`` parses one (module docstring)."""

    @classmethod
    def _missing_(cls, value: object) -> Any:
        raise ValueError(f"unknown {cls.label()} {value!r}; choose one of {cls.choices()}")

    @classmethod
    def label(cls) -> str:
        """What the choice is, in words: the class name split (``CosimMode`` -> "cosim mode")."""
        return re.sub(r"(?<=[a-z0-9])(?=[A-Z])", " ", cls.__name__).lower()

    @classmethod
    def choices(cls) -> str:
        """The values, comma-separated, in definition order."""
        return ", ".join(m.value for m in cls)
