"""Zenoh key expressions of a co-simulation run.

::

    hpcosim/run/<run_id>/can/tx        CAN frames plant -> controller
    hpcosim/run/<run_id>/can/rx        CAN frames controller -> plant
    hpcosim/run/<run_id>/ctrl/alive    liveliness token of the controller node
    hpcosim/run/<run_id>/plant/alive   liveliness token of the plant (co-simulation master)

Directions are named from the plant's side (the side that owns the recording): ``tx`` is
what the plant transmits, ``rx`` what it receives; the MCAP channels ``/can/tx`` and
``/can/rx`` use the same names. A run id is one key chunk of ``[A-Za-z0-9_.-]`` (no ``/``
and none of zenoh's wildcard or verbatim characters ``* $ ? #``).
"""

from __future__ import annotations

import enum
import re

ROOT = "hpcosim"
_RUN_ID = re.compile(r"[A-Za-z0-9_.-]{1,128}")


class Direction(enum.StrEnum):
    """Direction of CAN frames, named from the plant's side."""

    TX = "tx"  # plant -> controller (feedback, load, sim time)
    RX = "rx"  # controller -> plant (torque commands, heartbeat, status)

    @property
    def opposite(self) -> Direction:
        return Direction.RX if self is Direction.TX else Direction.TX


def validate_run_id(run_id: str) -> str:
    """Return ``run_id`` if it is a valid single key chunk, else raise ``ValueError``."""
    if not isinstance(run_id, str) or not _RUN_ID.fullmatch(run_id) or run_id in (".", ".."):
        raise ValueError(f"run id {run_id!r}: use 1-128 characters of [A-Za-z0-9_.-]")
    return run_id


def run_prefix(run_id: str) -> str:
    """``hpcosim/run/<run_id>``."""
    return f"{ROOT}/run/{validate_run_id(run_id)}"


def can_key(run_id: str, direction: Direction | str) -> str:
    """``hpcosim/run/<run_id>/can/<tx|rx>``."""
    return f"{run_prefix(run_id)}/can/{Direction(direction).value}"


def can_any_key(run_id: str) -> str:
    """Key expression matching both CAN directions of a run (for monitors)."""
    return f"{run_prefix(run_id)}/can/*"


def alive_key(run_id: str, node: str) -> str:
    """Liveliness token key of ``node`` (``ctrl`` or ``plant``) in a run."""
    if node not in ("ctrl", "plant"):
        raise ValueError(f"node {node!r}: expected 'ctrl' or 'plant'")
    return f"{run_prefix(run_id)}/{node}/alive"


def ctrl_alive_key(run_id: str) -> str:
    """``hpcosim/run/<run_id>/ctrl/alive``: the controller node's liveliness token."""
    return alive_key(run_id, "ctrl")


def plant_alive_key(run_id: str) -> str:
    """``hpcosim/run/<run_id>/plant/alive``: the plant's liveliness token."""
    return alive_key(run_id, "plant")


def parse_can_key(key: str) -> tuple[str, Direction]:
    """``(run_id, direction)`` of a CAN key; ``ValueError`` if ``key`` is not one."""
    parts = str(key).split("/")
    if len(parts) != 5 or parts[:2] != [ROOT, "run"] or parts[3] != "can":
        raise ValueError(f"{key!r} is not a {ROOT}/run/<run_id>/can/<tx|rx> key")
    try:
        return validate_run_id(parts[2]), Direction(parts[4])
    except ValueError as e:
        raise ValueError(f"{key!r}: {e}") from None
