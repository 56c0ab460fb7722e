"""A prosthesis controller for the multi-contact graph from AMPRO3's own sensors
(:class:`ContactPhasePD`): joint PD on the fitted gait's knee and ankle, with the gait's motor
torque as feedforward, both read at a phase the prosthesis measures itself.

- **Stance** (foot switch on: heel strike to toe-off, across ``ds_p``, ``ps``, ``ps_toe`` and
  ``ds_h``): the phase is the hip's forward progress over the heel's ground point, from the
  socket IMU's pitch and the knee and ankle encoders (the leg's kinematics, one function of
  the model): over the heel while the foot is on its heel or flat, over the toe plus the
  heel-to-toe length once the heel is up (whichever of the two is lower is on the ground).
  It rises monotonically over the whole stance, so one law runs the stance without deciding
  which domain it is in (a prototype that switched laws on a detected contact part fell when
  2 ms of the wrong law ran at the heel off).
- **Swing** (foot switch off): the residual thigh's place along the gait's own thigh pitch
  over its swing (``"thigh"``, the default: the socket IMU's pitch less the bias estimated
  in stance, :class:`~prosthesis_controller.thigh_phase.ThighSwingPhase`), which follows a
  person who swings faster or slower than the gait, with no clock; or with
  ``swing_phase="time"`` the time since toe-off over the gait's swing time.  Past 1 (a
  swing that outlasts the thigh's pace, or the gait's swing time) the law holds the landing
  posture at rest until the heel strike.  On the committed openOFM cycle the thigh's phase
  ends each swing within 0.3 % of the clock's (docs/gait-design.md, "The thigh's swing
  phase read to the peak").
- **Reference**: one stride of the gait as the model walks it (:func:`tables_from_walk`: the
  knee's and the ankle's angles, rates and motor torques against the phase), interpolated
  linearly in the phase (the torque has kinks at the contact transitions); a swing that
  outlasts the gait's holds the landing posture at rest until the heel strike.

Not the paper's CLF-QP: the product's ``clfqp`` runs the paper's two domains only.  Measured
with the simulated human on its feedback linearization (docs/gait-design.md): 20 steps on
openOFM's fits with heel offs at a 3 deg rise, 4 on its fit with heel offs from the rise's
onset (in ``ds_p`` the prosthesis foot lands flat 5 ms late and the trailing toe pulls); on
OpenSim's strides' fit 16, then the prosthesis's heel strike pulls (in a double support the
prosthesis's torque sets how the load is shared between the feet, and a joint PD's errors
there unload a contact).
"""

from __future__ import annotations

import bisect
import math
from dataclasses import dataclass, field

import numpy as np

from hp_model.domains import Domain
from hp_model.leg_kinematics import LegKinematics
from prosthesis_controller.interface import (
    Active,
    ControllerMode,
    ControlOutput,
    Diagnostics,
    QpOutcome,
)
from prosthesis_controller.measurement import Fault, ProsthesisMeasurement
from prosthesis_controller.thigh_phase import ThighSwingPhase


@dataclass(frozen=True)
class PhaseTable:
    """A stretch of the gait against its phase: ``phase`` (n,) non-decreasing from 0 to 1;
    ``values`` (n, 6): th_pk, th_pa (rad), their rates (rad/s), the motor torques (N m)."""

    phase: np.ndarray
    values: np.ndarray
    _phases: list[float] = field(init=False, repr=False, compare=False)
    _rows: list[list[float]] = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        # the phases as floats for bisect: a tick's search in ~0.3 us, not numpy's ~1.5 us
        # (the CLF-QP's tick is held to 40 us, benchmarks/bench_contact_controllers.py)
        object.__setattr__(self, "_phases", self.phase.tolist())
        object.__setattr__(self, "_rows", self.values.tolist())

    def at(self, s: float) -> tuple[float, ...]:
        """The values (6) at phase ``s``, linear between samples, clamped to the table's
        ends (as ``numpy.interp``, one search for the six columns)."""
        ph = self._phases
        s = min(max(s, ph[0]), ph[-1])
        i = min(max(bisect.bisect_right(ph, s) - 1, 0), len(ph) - 2)
        span = ph[i + 1] - ph[i]
        w = (s - ph[i]) / span if span > 0 else 0.0
        return tuple(a + w * (b - a) for a, b in zip(self._rows[i], self._rows[i + 1],
                                                     strict=True))


@dataclass(frozen=True)
class ContactGaitTables:
    """What :class:`ContactPhasePD` follows: the stance against its phase, the swing against
    its phase (time over ``swing_time`` (s) in the gait's walk), the hip's progress (m) at
    heel strike and toe-off, ``flat``: the stance phases between which the foot is flat on
    the ground (within :data:`FLAT_MARGIN` of where it lands flat and where its heel rises),
    and ``swing_pitch``: the socket's world pitch (rad) at the swing table's phases (the swing
    phase's measure: :class:`~prosthesis_controller.thigh_phase.ThighSwingPhase`)."""

    stance: PhaseTable
    swing: PhaseTable
    progress: tuple[float, float]
    swing_time: float
    flat: tuple[float, float]
    swing_pitch: np.ndarray


def blend_tables(a: ContactGaitTables, b: ContactGaitTables, w: float) -> ContactGaitTables:
    """The tables (1 - w) a + w b (0 <= w <= 1; two speeds' of a gait library: the
    references between them), on a's phase grids: b's values interpolated to a's phases,
    every number blended linearly."""

    def table(ta: PhaseTable, tb: PhaseTable) -> PhaseTable:
        vb = np.column_stack([np.interp(ta.phase, tb.phase, col) for col in tb.values.T])
        return PhaseTable(ta.phase.copy(), (1.0 - w) * ta.values + w * vb)

    def mix(x: float, y: float) -> float:
        return (1.0 - w) * x + w * y

    pitch = np.interp(a.swing.phase, b.swing.phase, b.swing_pitch)
    return ContactGaitTables(
        table(a.stance, b.stance), table(a.swing, b.swing),
        (mix(a.progress[0], b.progress[0]), mix(a.progress[1], b.progress[1])),
        mix(a.swing_time, b.swing_time), (mix(a.flat[0], b.flat[0]), mix(a.flat[1], b.flat[1])),
        (1.0 - w) * a.swing_pitch + w * pitch)


#: a foot with its heel within this angle of its toe (rad) is flat
FLAT_PITCH = 1e-3
#: the part of the flat stance left out at each end (of its phase span) for the IMU's bias
FLAT_MARGIN = 0.1


def first_stride(contact: np.ndarray) -> tuple[int, int, int]:
    """Sample indices of a walk's first heel strike (the foot switch turning on), the
    toe-off after it and the next heel strike.  ValueError without them."""
    c = np.asarray(contact, bool)
    on = np.flatnonzero(~c[:-1] & c[1:]) + 1
    off = np.flatnonzero(c[:-1] & ~c[1:]) + 1
    i0 = int(on[0]) if on.size else None
    i1 = next((int(i) for i in off if i0 is not None and i > i0), None)
    i2 = next((int(i) for i in on if i1 is not None and i > i1), None)
    if i0 is None or i1 is None or i2 is None:
        raise ValueError("the walk holds no stance from a heel strike and the swing after it")
    return i0, i1, i2


def tables_from_walk(leg: LegKinematics, t: np.ndarray, sensed: np.ndarray,
                     contact: np.ndarray, torque: np.ndarray) -> ContactGaitTables:
    """The tables of a walk sampled each period: ``t`` (n,) s; ``sensed`` (n, 5): socket
    pitch, knee, ankle (rad), knee and ankle rates (rad/s); ``contact`` (n,) the foot switch;
    ``torque`` (n, 2) the motor torques (N m).  From its first stance that starts with a heel
    strike (the switch turning on) and the swing after it.  The gait as the model walks it:
    the feedforward is the torque of that walk, not the fit's node torques, which belong to
    the fit's own accelerations (the regressed curves the walker follows differ from them by
    up to 0.7 N m at the motor).  ValueError without such a stance and swing, or if the
    stance's phase does not rise."""
    i0, i1, i2 = first_stride(contact)
    x = np.asarray(sensed, float)
    p, rise = np.array([leg.sense(*x[i, :3]) for i in range(i0, i1)]).T
    if not np.all(np.diff(p) > -1e-6):
        k = int(np.argmin(np.diff(p)))
        raise ValueError(f"the stance's phase does not rise (sample {k}: {p[k]:.4f} -> "
                         f"{p[k + 1]:.4f} m)")
    vals = np.c_[x[:, 1:5], np.asarray(torque, float)]
    swing_time = float(t[i2] - t[i1])
    phase = (p - p[0]) / (p[-1] - p[0])
    flat = phase[np.abs(rise) < FLAT_PITCH]
    if flat.size < 2:
        raise ValueError("the walk's stance has no flat foot")
    margin = FLAT_MARGIN * float(flat[-1] - flat[0])
    return ContactGaitTables(PhaseTable(phase, vals[i0:i1]),
                             PhaseTable((t[i1:i2] - t[i1]) / swing_time, vals[i1:i2]),
                             (float(p[0]), float(p[-1])), swing_time,
                             (float(flat[0]) + margin, float(flat[-1]) - margin),
                             x[i1:i2, 0].copy())


@dataclass(frozen=True)
class PDGains:
    """Joint-side gains: stiffness (N m/rad) and damping (N m s/rad), (knee, ankle)."""

    kp: tuple[float, float]
    kd: tuple[float, float]


#: the time constant of the IMU bias's estimate (s)
BIAS_TIME = 0.05

#: how the swing's phase is measured (:class:`ContactPhasePD`): the residual thigh's place
#: along the gait's swing (:mod:`prosthesis_controller.thigh_phase`, the default) or the
#: time since toe-off over the gait's swing time (a clock)
SWING_PHASES = ("thigh", "time")
DEFAULT_SWING_PHASE = "thigh"

#: the defaults (docs/gait-design.md: the window of gains that walk is narrow)
STANCE_GAINS = PDGains((100.0, 100.0), (3.0, 3.0))
SWING_GAINS = PDGains((100.0, 100.0), (3.0, 3.0))


def control_output(torque: tuple[float, float], phase: float, domain: Domain,
                   mode: ControllerMode, fallbacks: int, *, V: float = 0.0, rho: float = 0.0,
                   qp: QpOutcome = QpOutcome.NOT_RUN) -> ControlOutput:
    """A multi-contact controller's tick as the product's controllers report one
    (:class:`~prosthesis_controller.interface.ControlOutput`; a non-finite phase reads 0;
    mode fault: a measurement with a non-finite field)."""
    fault = Fault.NON_FINITE if mode == ControllerMode.FAULT else Fault.NONE
    return ControlOutput(np.array(torque), Diagnostics(
        phase if math.isfinite(phase) else 0.0, V, rho, qp, Active.NONE, fallbacks,
        int(fault), domain, mode))


class ContactPhasePD:
    """The controller of the module docstring, one tick per measurement: motor torques
    (knee, ankle; N m), clamped to ``limits`` (N m, motor side), zero for a measurement it
    cannot use (a non-finite field or no IMU pitch: mode fault).  Its diagnostics' domain
    is ps in stance, pns in swing."""

    name = "contact-pd"

    def __init__(self, tables: ContactGaitTables, leg: LegKinematics,
                 gear: tuple[float, float], limits: tuple[float, float],
                 stance: PDGains = STANCE_GAINS, swing: PDGains = SWING_GAINS,
                 swing_phase: str = DEFAULT_SWING_PHASE) -> None:
        if swing_phase not in SWING_PHASES:
            raise ValueError(f"swing_phase {swing_phase!r}: choose from "
                             f"{', '.join(SWING_PHASES)}")
        self.tables, self.leg, self.swing_phase = tables, leg, swing_phase
        #: what the law was made with (its file, :mod:`prosthesis_controller.gait_tables`)
        self.stance_gains, self.swing_gains = stance, swing
        self._gear = (float(gear[0]), float(gear[1]))
        self._limits = (float(limits[0]), float(limits[1]))
        self._gains = {True: (stance.kp, stance.kd), False: (swing.kp, swing.kd)}
        self.reset()

    @property
    def gear(self) -> tuple[float, float]:
        """The gear ratios (knee, ankle)."""
        return self._gear

    @property
    def limits(self) -> tuple[float, float]:
        """The motor torque limits (knee, ankle; N m)."""
        return self._limits

    def reset(self, torque: tuple[float, float] | None = None) -> None:
        """Forget the phase's and the bias estimate's state (``torque``: the controller
        interface's; this law holds no torque of its own)."""
        self.fallbacks = 0  # ticks that answered a measurement it could not use
        self._in_stance: bool | None = None
        self._t_off: float | None = None
        #: the last tick's phase (stance: the progress phase; swing: the time's or thigh's)
        self.phase = math.nan
        #: the last stance tick's sensed rise of the heel over the toe (rad, less the bias
        #: estimate: LegKinematics.sense; negative while the foot is on its heel, 0 flat)
        self.rise = 0.0
        #: the estimate of the IMU pitch's bias (rad), subtracted from its readings, and the
        #: time of its last update (s)
        self.imu_bias = 0.0
        self._t_bias: float | None = None
        #: the thigh's swing phase (its flexion range learnt from the walk's swings)
        self._thigh = (ThighSwingPhase(self.tables.swing.phase, self.tables.swing_pitch)
                       if self.swing_phase == "thigh" else None)

    def blended(self, other: ContactPhasePD, w: float) -> ContactPhasePD:
        """This law with its tables blended with ``other``'s, (1 - w) these + w other's
        (:func:`blend_tables`; the same leg, motors, gains and swing phase)."""
        return ContactPhasePD(blend_tables(self.tables, other.tables, w), self.leg, self._gear,
                              self._limits, self.stance_gains, self.swing_gains,
                              self.swing_phase)

    @property
    def in_stance(self) -> bool | None:
        """Whether the last tick was in stance (None before the first)."""
        return self._in_stance

    def take_over(self, other: ContactPhasePD) -> None:
        """Continue from ``other``'s state (the same leg, another gait's tables: a switch of
        speed, :mod:`prosthesis_controller.speed_following`): its phase's, its IMU bias
        estimate's and its counts."""
        self.fallbacks, self._in_stance, self._t_off = (other.fallbacks, other._in_stance,
                                                        other._t_off)
        if self._thigh is not None and other._thigh is not None:
            self._thigh.take_over(other._thigh)
        self.phase, self.imu_bias, self._t_bias = other.phase, other.imu_bias, other._t_bias

    def stance_phase(self, m: ProsthesisMeasurement) -> float:
        """The stance phase of a measurement: the hip's progress over the heel's ground point
        from the heel strike's (0) to the toe-off's (1) (module docstring), from the IMU's
        pitch less its estimated bias.  While the gait's foot is flat (``tables.flat``) the
        heel's sensed rise over the toe is that bias's residual (a flat foot's is zero, and
        the bias rotates the whole leg): the estimate follows it with the time constant
        :data:`BIAS_TIME` (a level floor assumed; 0.5 deg of bias moves the stance phase by
        ~1.3 %, and without it half of the walks with 0.25 deg fell, docs/gait-design.md)."""
        p, rise = self.leg.sense(m.socket_pitch - self.imu_bias, m.knee_angle, m.ankle_angle)
        self.rise = rise
        p0, p1 = self.tables.progress
        s = (p - p0) / (p1 - p0)
        f0, f1 = self.tables.flat
        if f0 <= s <= f1:
            if self._t_bias is not None:
                k = min(max(m.t - self._t_bias, 0.0) / BIAS_TIME, 1.0)
                self.imu_bias += k * rise
            self._t_bias = m.t
        else:
            self._t_bias = None
        return s

    def tick(self, m: ProsthesisMeasurement) -> ControlOutput:
        fields = (m.t, m.knee_angle, m.ankle_angle, m.knee_vel, m.ankle_vel, m.socket_pitch)
        if not all(math.isfinite(v) for v in fields):
            self.fallbacks += 1
            return control_output((0.0, 0.0), self.phase, Domain.PNS, ControllerMode.FAULT,
                                  self.fallbacks)
        u = self.torque(m, self.reference(m))
        stance = bool(m.contact)
        return control_output(u, self.phase, Domain.PS if stance else Domain.PNS,
                              ControllerMode.STANCE if stance else ControllerMode.SWING,
                              self.fallbacks)

    def reference(self, m: ProsthesisMeasurement) -> tuple[float, ...]:
        """The gait at the measurement's phase (which it sets: :attr:`phase`): th_pk, th_pa
        (rad), their rates (rad/s), the motor torques (N m); ``m`` finite.  Past the swing
        table's end (a swing longer than the gait's, no heel strike yet: a person slower
        than the gait) the table's last angles at rest, with no torque of the gait's: that
        torque is its last instant's (on the packaged person's gait +44 N m of knee flexion
        into the heel strike, with the knee's rate at 8 rad/s: held, they flexed the waiting
        knee to 55 deg and no heel strike came, docs/gait-design.md)."""
        tab = self.tables
        stance = bool(m.contact)
        if stance:
            s = self.stance_phase(m)
            ref = tab.stance.at(s)
        else:
            s = self.swing_phase_of(m)
            ref = tab.swing.at(s)
            if s > 1.0:  # the swing outlasts the gait's: hold its landing posture, at rest
                ref = (ref[0], ref[1], 0.0, 0.0, 0.0, 0.0)
        self._in_stance, self.phase = stance, s
        return ref

    def swing_phase_of(self, m: ProsthesisMeasurement) -> float:
        """The swing phase of a measurement in swing (``swing_phase``: the time since toe-off
        over the gait's swing time, or the thigh's)."""
        toe_off = self._in_stance is not False  # (or a start in swing)
        if self._thigh is not None:
            pitch = m.socket_pitch - self.imu_bias
            if toe_off:
                self._thigh.reset(m.t, pitch)
            return self._thigh.update(m.t, pitch)
        if toe_off or self._t_off is None:
            self._t_off = m.t
        return (m.t - self._t_off) / self.tables.swing_time

    def torque(self, m: ProsthesisMeasurement, ref: tuple[float, ...]) -> tuple[float, float]:
        """The law's motor torques (N m, within the limits) about the reference ``ref``
        (:meth:`reference`)."""
        (kpk, kpa), (kdk, kda) = self._gains[bool(m.contact)]
        (gk, ga), (lk, la) = self._gear, self._limits
        rk, ra, rvk, rva, fk, fa = ref
        uk = fk + (kpk * (rk - m.knee_angle) + kdk * (rvk - m.knee_vel)) / gk
        ua = fa + (kpa * (ra - m.ankle_angle) + kda * (rva - m.ankle_vel)) / ga
        return min(max(uk, -lk), lk), min(max(ua, -la), la)
