"""The controller side of the closed loop: a link turns the plant's observation into the
motor torque of the period.

- :class:`ControllerLink`: a prosthesis controller in this process, fed what AMPRO3 senses
  through an :class:`Encoder` (noise, quantization), optionally quantized as the CAN frames
  quantize it (``quantize=True``: the in-process twin of a co-simulation).
- :class:`OracleLink`: no controller; the plant's own feedback linearization of the
  prosthesis outputs (perfect knowledge and sensing: the walkability label).
- The CAN link over a python-can bus with the fault plan is
  :class:`orchestrator.cosim.can_link.CanLink`.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import NamedTuple, Protocol

import numpy as np

from orchestrator.loop.plant import Observation, Vector
from prosthesis_controller import ProsthesisMeasurement
from prosthesis_controller.interface import Controller, ControllerMode


class Command(NamedTuple):
    """A link's answer for one period."""

    torque: Vector | None  # (2,) motor torques (N m); None: the plant's own law
    mode: ControllerMode | str = ""  # the controller's mode of the tick ("" over CAN)
    V: float | None = 0.0  # CLF value V_eps; None: not reported (over CAN: CtrlClf absent)
    rho: float | None = 0.0  # CLF-QP relaxation; None: not reported (no relaxation)
    fallback_count: int = 0
    fault: str = ""  # non-empty: the link failed (watchdog, lost peer); the run ends


class Link(Protocol):
    """The controller side: ``exchange`` once per period; ``pace(k)`` after the plant
    advanced to period k (a real-time link waits for the wall clock there)."""

    def exchange(self, obs: Observation) -> Command: ...

    def pace(self, k: int) -> None: ...


class LateLink(Link, Protocol):
    """A link that sends before it waits (``idle_after_send`` true: the co-simulation's CAN
    link in lockstep): ``exchange(obs, idle)`` calls ``idle()`` once, after the period's
    frames went out and before it waits for the reply; the Command it returns may be
    provisional until ``settle(cmd)`` completes it (see :func:`orchestrator.loop.run_loop`)."""

    @property
    def idle_after_send(self) -> bool: ...

    def exchange(self, obs: Observation, idle: Callable[[], None] | None = None
                 ) -> Command: ...

    def settle(self, cmd: Command) -> Command: ...


@dataclass(frozen=True)
class Encoder:
    """AMPRO3's sensors: on the joint encoders zero-mean white noise (standard deviations)
    and quantization steps (round to the nearest multiple; 0: none) on the angles (rad) and
    velocities (rad/s); on the IMU's socket pitch a constant ``imu_bias`` and white noise
    ``imu_noise`` (rad); ``seed`` makes the noise of a run reproducible."""

    angle_noise: float = 0.0
    velocity_noise: float = 0.0
    angle_resolution: float = 0.0
    velocity_resolution: float = 0.0
    imu_bias: float = 0.0
    imu_noise: float = 0.0
    seed: int = 0

    def __post_init__(self) -> None:
        for name in ("angle_noise", "velocity_noise", "angle_resolution",
                     "velocity_resolution", "imu_noise"):
            v = getattr(self, name)
            if not (np.isfinite(v) and v >= 0):
                raise ValueError(f"encoder {name} must be finite and >= 0, got {v}")
        if not np.isfinite(self.imu_bias):
            raise ValueError(f"encoder imu_bias must be finite, got {self.imu_bias}")

    @property
    def ideal(self) -> bool:
        return (self.angle_noise, self.velocity_noise, self.angle_resolution,
                self.velocity_resolution, self.imu_bias, self.imu_noise) == (0.0,) * 6

    def pitch(self, rng: np.random.Generator, pitch: float) -> float:
        """The socket pitch (rad) as the IMU reports it (the noise drawn only when there
        is some, so the encoders' noise sequence does not depend on the IMU)."""
        if self.imu_noise > 0:
            pitch += self.imu_noise * float(rng.standard_normal())
        return pitch + self.imu_bias

    def read(self, rng: np.random.Generator, angles: np.ndarray, vel: np.ndarray
             ) -> tuple[np.ndarray, np.ndarray]:
        """(angles, velocities) as the encoders report them."""
        a = angles + self.angle_noise * rng.standard_normal(2)
        v = vel + self.velocity_noise * rng.standard_normal(2)
        if self.angle_resolution > 0:
            a = np.round(a / self.angle_resolution) * self.angle_resolution
        if self.velocity_resolution > 0:
            v = np.round(v / self.velocity_resolution) * self.velocity_resolution
        return a, v


IDEAL_ENCODER = Encoder()


def measurement(obs: Observation, encoder: Encoder = IDEAL_ENCODER,
                rng: np.random.Generator | None = None) -> ProsthesisMeasurement:
    """What the controller receives for observation ``obs`` through ``encoder``."""
    s = obs.sensed
    if encoder.ideal:
        return ProsthesisMeasurement(obs.t, s.knee_angle, s.ankle_angle, s.knee_velocity,
                                     s.ankle_velocity, s.foot_load, s.contact, s.socket_pitch)
    ang = np.array([s.knee_angle, s.ankle_angle], float)
    vel = np.array([s.knee_velocity, s.ankle_velocity], float)
    pitch = s.socket_pitch
    g = rng if rng is not None else np.random.default_rng(encoder.seed)
    ang, vel = encoder.read(g, ang, vel)
    if np.isfinite(pitch):
        pitch = encoder.pitch(g, pitch)
    return ProsthesisMeasurement(t=float(obs.t), knee_angle=float(ang[0]),
                                 ankle_angle=float(ang[1]), knee_vel=float(vel[0]),
                                 ankle_vel=float(vel[1]), foot_load=s.foot_load,
                                 contact=s.contact, socket_pitch=float(pitch))


def bus_quantized(m: ProsthesisMeasurement) -> ProsthesisMeasurement:
    """``m`` as the controller node decodes it from AMPRO3's frames (the codec's
    resolution; time in whole microseconds)."""
    from bus_schemas.transport import codec

    pitch = m.socket_pitch
    return ProsthesisMeasurement(
        round(m.t * 1e6) * 1e-6, codec.quantize_angle(m.knee_angle),
        codec.quantize_angle(m.ankle_angle), codec.quantize_velocity(m.knee_vel),
        codec.quantize_velocity(m.ankle_vel), codec.quantize_load(m.foot_load), m.contact,
        codec.quantize_pitch(pitch) if np.isfinite(pitch) else pitch)


class ControllerLink:
    """A prosthesis controller in this process (reset here).  ``quantize``: measurements
    and torques at the CAN frames' resolution (what a co-simulation's controller sees)."""

    def __init__(self, controller: Controller, encoder: Encoder = IDEAL_ENCODER, *,
                 quantize: bool = False) -> None:
        self.ctrl, self.encoder, self.quantize = controller, encoder, quantize
        self.rng = np.random.default_rng(encoder.seed)
        controller.reset()

    def exchange(self, obs: Observation) -> Command:
        m = measurement(obs, self.encoder, self.rng)
        if self.quantize:
            m = bus_quantized(m)
        out = self.ctrl.tick(m)
        dg = out.diagnostics
        u = np.array(out.torque, float)
        if self.quantize:
            from bus_schemas.transport import codec

            u = np.array([codec.quantize_torque(float(u[0])),
                          codec.quantize_torque(float(u[1]))])
        return Command(u, dg.mode, float(dg.V), float(dg.rho), int(dg.fallback_count))

    def pace(self, k: int) -> None:
        """In process: no wall clock to keep."""


class OracleLink:
    """No prosthesis controller: the plant's own feedback linearization (mode full)."""

    def exchange(self, obs: Observation) -> Command:
        return Command(None, ControllerMode.ORACLE)

    def pace(self, k: int) -> None:
        """In process: no wall clock to keep."""
