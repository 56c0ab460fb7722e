"""The value a decoder will see: :func:`quantize` clamps to the DBC range and rounds half
to even to the signal's step, bit for bit as encoding then decoding would (scalars or numpy
arrays); ``quantize_*`` name the protocol's common signals; :func:`scalar_quantizer` binds
one signal's constants for a hot path.  Use them for an in-process simulation that must
match the lockstep co-simulation."""

from __future__ import annotations

import functools
from collections.abc import Callable
from typing import Any

import numpy as np

from bus_schemas.transport.protocol import FrameId, FrameSpec, frame_spec


@functools.cache
def _signal(frame: int | str, signal: str) -> tuple[FrameSpec, Any]:
    """(frame spec, signal) of ``frame.signal``, looked up once (the recordings quantize
    every measurement)."""
    spec = frame_spec(frame)
    return spec, spec.signal(signal)


def quantize(frame: int | str, signal: str, x: Any) -> Any:
    """The value a decoder sees for ``x`` sent as ``frame.signal``: clamp to the DBC range,
    round half to even to the step, scale back. Scalars give floats, arrays give arrays
    (bit-identical to the scalar path). NaN raises ``ValueError``."""
    spec, sig = _signal(frame, signal)
    if isinstance(x, np.ndarray | list | tuple):
        a = np.asarray(x, dtype=float)
        if np.isnan(a).any():
            raise ValueError(f"{spec.name}.{signal}: NaN cannot be encoded")
        raw = np.round((np.clip(a, sig.minimum, sig.maximum) - sig.offset) / sig.scale)
        return raw * sig.scale + sig.offset
    v = float(x)
    if v != v:
        raise ValueError(f"{spec.name}.{signal}: NaN cannot be encoded")
    v = sig.minimum if v < sig.minimum else sig.maximum if v > sig.maximum else v
    if not sig.linear:
        return round(v)
    return round((v - sig.offset) / sig.scale) * sig.scale + sig.offset


def scalar_quantizer(frame: int | str, signal: str) -> Callable[[float], float]:
    """:func:`quantize` of ``frame.signal`` for a scalar, the signal's constants bound once
    (the same operations, so the same floats: for a hot path quantizing every tick)."""
    spec, sig = _signal(frame, signal)
    lo, hi, off, scale, linear = sig.minimum, sig.maximum, sig.offset, sig.scale, sig.linear
    name = f"{spec.name}.{signal}"

    def q(x: float) -> float:
        v = float(x)
        if v != v:
            raise ValueError(f"{name}: NaN cannot be encoded")
        v = lo if v < lo else hi if v > hi else v
        if not linear:
            return round(v)
        return round((v - off) / scale) * scale + off
    return q


def quantize_angle(x: Any) -> Any:
    """Joint angle as decoded (step 1e-5 rad, clamped to +-3.2 rad)."""
    return quantize(FrameId.KNEE_FEEDBACK, "KneeAngle", x)


def quantize_velocity(x: Any) -> Any:
    """Joint velocity as decoded (step 1e-4 rad/s, clamped to +-50 rad/s)."""
    return quantize(FrameId.KNEE_FEEDBACK, "KneeVelocity", x)


def quantize_torque(x: Any) -> Any:
    """Motor torque command as decoded (step 1e-6 N m, clamped to +-5 N m)."""
    return quantize(FrameId.TORQUE_CMD, "KneeTorqueCmd", x)


def quantize_load(x: Any) -> Any:
    """Foot normal load as decoded (step 0.1 N, clamped to [-1000, 3000] N)."""
    return quantize(FrameId.FOOT_LOAD, "FootNormalLoad", x)


def quantize_clf_v(x: Any) -> Any:
    """CLF value V as decoded from CtrlClf (step 1e-5, clamped to [0, 167.77215])."""
    return quantize(FrameId.CTRL_CLF, "ClfV", x)


def quantize_clf_rho(x: Any) -> Any:
    """CLF-QP relaxation rho as decoded from CtrlClf (step 1e-3, clamped to
    [0, 16777.215])."""
    return quantize(FrameId.CTRL_CLF, "ClfRho", x)


def quantize_pitch(x: Any) -> Any:
    """Socket pitch as decoded (step 1e-5 rad, clamped to +-3.2 rad)."""
    return quantize(FrameId.SOCKET_IMU, "SocketPitch", x)

