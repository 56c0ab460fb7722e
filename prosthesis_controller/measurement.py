"""What the controller senses (DESIGN.md: only what AMPRO3 can sense) and its validation.

Angles are the model's joint coordinates th_pk, th_pa (hp_model conventions: pitch about
+y, knee flexion positive, ankle plantarflexion positive, all zero = straight leg, foot at
right angles to the shin).  A mapping from encoder counts to these belongs to the CAN port.

:func:`validate` never raises: a bad measurement yields a non-zero :class:`Fault` flag
set, and the controller answers with its fault fallback.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from enum import IntFlag


@dataclass(frozen=True, slots=True)
class ProsthesisMeasurement:
    """One sample of the prosthesis sensors.

    t: s (monotonic); knee_angle, ankle_angle: rad; knee_vel, ankle_vel: rad/s;
    foot_load: N (axial load cell, >= 0); contact: foot switch; socket_pitch: rad, world
    pitch of the prosthesis top link from AMPRO3's IMU (about +y, the model's th_B + th_rh +
    th_f), NaN when there is none."""

    t: float
    knee_angle: float
    ankle_angle: float
    knee_vel: float
    ankle_vel: float
    foot_load: float = 0.0
    contact: bool = False
    socket_pitch: float = math.nan


class Fault(IntFlag):
    """Why a measurement was refused (bits; 0 = valid)."""

    NONE = 0
    NON_FINITE = 1  # a NaN or inf in any numeric field
    ANGLE_RANGE = 2  # knee or ankle angle outside the configured range
    SPEED_RANGE = 4  # a joint speed above the configured maximum
    LOAD_RANGE = 8  # foot load outside the configured range
    TIME = 16  # time not increasing
    TYPE = 32  # a field that is not a number (or not a measurement at all)


def validate(m: object, t_prev: float, knee_range: tuple[float, float],
             ankle_range: tuple[float, float], max_speed: float,
             load_range: tuple[float, float]) -> Fault:
    """Fault flags of a measurement; ``t_prev`` is the last accepted time (-inf at first)."""
    return read(m, t_prev, knee_range, ankle_range, max_speed, load_range)[0]


_UNREAD = (math.nan,) * 6 + (False, math.nan)


def read(m: object, t_prev: float, knee_range: tuple[float, float],
         ankle_range: tuple[float, float], max_speed: float,
         load_range: tuple[float, float]
         ) -> tuple[Fault, float, float, float, float, float, float, bool, float]:
    """:func:`validate` and the fields it read, as the controller's tick uses them:
    (fault, t, knee_angle, ankle_angle, knee_vel, ankle_vel, foot_load, contact,
    socket_pitch), floats and a bool (NaNs and False for a ``Fault.TYPE``)."""
    try:
        t = float(m.t)  # type: ignore[attr-defined]
        qk, qa = float(m.knee_angle), float(m.ankle_angle)  # type: ignore[attr-defined]
        vk, va = float(m.knee_vel), float(m.ankle_vel)  # type: ignore[attr-defined]
        load = float(m.foot_load)  # type: ignore[attr-defined]
        contact = m.contact  # type: ignore[attr-defined]
        pitch = float(getattr(m, "socket_pitch", math.nan))
    except (AttributeError, TypeError, ValueError):
        return (Fault.TYPE, *_UNREAD)
    if contact not in (True, False):  # bool, 0/1, numpy bools; not "yes", NaN or 0.5
        return (Fault.TYPE, *_UNREAD)
    isf = math.isfinite
    if not (isf(t) and isf(qk) and isf(qa) and isf(vk) and isf(va) and isf(load)) \
            or math.isinf(pitch):  # a NaN pitch: no IMU
        return Fault.NON_FINITE, t, qk, qa, vk, va, load, bool(contact), pitch
    f = Fault.NONE
    if not (knee_range[0] <= qk <= knee_range[1] and ankle_range[0] <= qa <= ankle_range[1]):
        f |= Fault.ANGLE_RANGE
    if abs(vk) > max_speed or abs(va) > max_speed:
        f |= Fault.SPEED_RANGE
    if not load_range[0] <= load <= load_range[1]:
        f |= Fault.LOAD_RANGE
    if not t > t_prev:
        f |= Fault.TIME
    return f, t, qk, qa, vk, va, load, bool(contact), pitch
