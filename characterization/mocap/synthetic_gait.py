"""A plausible periodic gait of the human-prosthesis model with step-to-step variability.

The template is written in task space, as a walker's footfalls: per stride k (starting at
prosthesis foot-flat contact) a prosthesis step and a human step with random lengths, a
stride time and double-support fractions; the hip moves forward monotonically (PCHIP
through the double-support midpoints, halfway between the feet), rises and falls between
double support (low) and mid single support (high); the trunk leans with a small
twice-per-stride oscillation; each swing foot moves on a smooth path (quintic in x, a
clearance bump in z, a toe-up pitch bump) from footprint to footprint and is flat on the
ground in stance; the hip height is capped smoothly by what both legs reach.
Two-link inverse kinematics (knee flexing forward) turns hip and ankle positions into the
model's coordinates q (hp_model conventions: hip flexion negative, knee flexion positive,
plantarflexion positive).  Frame positions then come from the model's own
forward kinematics (:mod:`characterization.mocap.synthetic_subject`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.interpolate import PchipInterpolator
from scipy.signal import butter, sosfiltfilt

from characterization.mocap.take import MocapError


@dataclass(frozen=True)
class GaitParams:
    """Nominal gait and its stride-to-stride variability (SD, same units); SI units."""

    stride_time: float = 1.15  # s
    step_length: float = 0.42  # m, ankle to ankle at contact, each side
    double_support: float = 0.08  # fraction of the stride, each of the two
    hip_height_ds: float = 0.840  # m, hip above the floor at double support
    hip_height_ss: float = 0.875  # m, at mid single support
    trunk_lean: float = 0.06  # rad, forward
    trunk_sway: float = 0.02  # rad, amplitude of the twice-per-stride oscillation
    clearance: float = 0.05  # m, sole above the floor at mid swing
    toe_up_human: float = 0.15  # rad, foot pitch at mid swing (toe up)
    toe_up_prosthesis: float = 0.06  # rad
    max_leg_extension: float = 0.993  # hip-ankle distance / leg length, at most
    height_smoothing: float = 0.004  # m, of the smooth minimum limiting the hip height
    height_lowpass_hz: float = 4.0  # zero-phase low-pass of the hip height (0 = off)
    #: the foot's roll in stance (all 0: flat from touchdown to lift-off, as before): it
    #: lands on its heel pitched toe-up by ``heel_strike_pitch`` (rad) and rolls flat about
    #: the heel by the other foot's lift-off; its heel rises ``heel_rise`` s before the other
    #: foot's touchdown, the foot turning about its toe (pitch rising as the square of time)
    #: to ``toe_off_pitch`` (rad, toe down) at its lift-off
    heel_strike_pitch: float = 0.0
    toe_off_pitch: float = 0.0
    heel_rise: float = 0.0
    sd_stride_time: float = 0.03
    sd_step_length: float = 0.015
    sd_double_support: float = 0.01
    sd_height: float = 0.004
    sd_clearance: float = 0.006


@dataclass(frozen=True)
class GaitEvents:
    """Contact events (s) and footprints (sole x, m) of every stride (index k)."""

    p_land: np.ndarray
    h_lift: np.ndarray
    h_land: np.ndarray
    p_lift: np.ndarray
    p_print: np.ndarray
    h_print: np.ndarray


def _quintic(s: np.ndarray) -> np.ndarray:
    return s**3 * (10 - 15 * s + 6 * s**2)


def _bump(s: np.ndarray) -> np.ndarray:
    return 64.0 * s**3 * (1 - s) ** 3


def gait_events(n_strides: int, p: GaitParams, rng: np.random.Generator) -> GaitEvents:
    """Random events for strides 0..n_strides-1 (stride 0 starts at t = 0)."""
    T = p.stride_time + p.sd_stride_time * rng.standard_normal(n_strides)
    ds1 = (p.double_support + p.sd_double_support * rng.standard_normal(n_strides)) * T
    ds2 = (p.double_support + p.sd_double_support * rng.standard_normal(n_strides)) * T
    half = (0.5 + 0.01 * rng.standard_normal(n_strides)) * T
    sp = p.step_length + p.sd_step_length * rng.standard_normal(n_strides)
    sh = p.step_length + p.sd_step_length * rng.standard_normal(n_strides)
    a = np.concatenate([[0.0], np.cumsum(T)[:-1]])
    p_print = np.cumsum(sp + np.concatenate([[0.0], sh[:-1]]))
    return GaitEvents(p_land=a, h_lift=a + ds1, h_land=a + half, p_lift=a + half + ds2,
                      p_print=p_print, h_print=p_print + sh)


@dataclass(frozen=True)
class _Roll:
    """One foot's roll (:class:`GaitParams`): per landing i the time it is flat
    (``flats[i]``), per lift-off i the time its heel rises (``rises[i]``); pitches (rad) and
    the heel and toe lengths (m) of :class:`LegGeometry`."""

    flats: np.ndarray
    rises: np.ndarray
    strike_pitch: float = 0.0
    off_pitch: float = 0.0
    heel: float = 0.0
    toe: float = 0.0

    def pose(self, print_x: float, pitch: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The sole point under the ankle (x, z) of a foot at ``pitch`` (toe down positive)
        on the print ``print_x`` (its flat sole point): turned about the heel when toe-up,
        about the toe when toe-down."""
        heel_x, toe_x = print_x - self.heel, print_x + self.toe
        up = pitch < 0
        x = np.where(up, heel_x + self.heel * np.cos(pitch), toe_x - self.toe * np.cos(pitch))
        z = np.where(up, -self.heel * np.sin(pitch), self.toe * np.sin(pitch))
        return x, z


def _foot(t: np.ndarray, lifts: np.ndarray, lands: np.ndarray, prints_from: np.ndarray,
          prints_to: np.ndarray, clearance: np.ndarray, toe_up: float,
          roll: _Roll | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Sole point (x, z) and foot pitch of one foot; swing i goes lifts[i] -> lands[i], from
    the pose of its lift-off to that of its landing (flat both without a ``roll``)."""
    x = np.full_like(t, prints_from[0])
    z = np.zeros_like(t)
    ph = np.zeros_like(t)
    for i in range(len(lifts)):
        after = t >= lands[i]
        x[after] = prints_to[i]
        z[after], ph[after] = 0.0, 0.0
        start, end = (0.0, 0.0), (0.0, 0.0)
        pitch0, pitch1 = 0.0, 0.0
        if roll is not None:
            rise = (t >= roll.rises[i]) & (t < lifts[i])
            u = (t[rise] - roll.rises[i]) / (lifts[i] - roll.rises[i])
            ph[rise] = roll.off_pitch * u**2
            x[rise], z[rise] = roll.pose(prints_from[i], ph[rise])
            down = (t >= lands[i]) & (t < roll.flats[i])
            u = (t[down] - lands[i]) / (roll.flats[i] - lands[i])
            ph[down] = -roll.strike_pitch * (1.0 - u)
            x[down], z[down] = roll.pose(prints_to[i], ph[down])
            pitch0, pitch1 = roll.off_pitch, -roll.strike_pitch
            a, b = roll.pose(prints_from[i], np.array([pitch0])), \
                roll.pose(prints_to[i], np.array([pitch1]))
            start = (float(a[0][0]) - prints_from[i], float(a[1][0]))
            end = (float(b[0][0]) - prints_to[i], float(b[1][0]))
        sw = (t >= lifts[i]) & (t < lands[i])
        s = (t[sw] - lifts[i]) / (lands[i] - lifts[i])
        blend = _quintic(s)
        x0, x1 = prints_from[i] + start[0], prints_to[i] + end[0]
        x[sw] = x0 + (x1 - x0) * blend
        z[sw] = start[1] + (end[1] - start[1]) * blend + clearance[i] * _bump(s)
        ph[sw] = pitch0 + (pitch1 - pitch0) * blend - toe_up * _bump(s)
    return x, z, ph


def _two_link_ik(hip: np.ndarray, ankle: np.ndarray, l1: float, l2: float, what: str
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(thigh pitch, shank pitch, knee flexion) for hip and ankle (n, 2) positions."""
    v = hip - ankle
    d = np.hypot(v[:, 0], v[:, 1])
    if np.any(d >= l1 + l2 - 1e-4) or np.any(d <= abs(l1 - l2)):
        i = int(np.argmax((d >= l1 + l2 - 1e-4) | (d <= abs(l1 - l2))))
        raise MocapError(f"gait template: {what} cannot reach (hip-ankle {d[i]:.4f} m, leg "
                         f"{l1 + l2:.4f} m) at sample {i}")
    psi = np.arctan2(v[:, 0], v[:, 1])
    beta = np.arccos(np.clip((l2**2 + d**2 - l1**2) / (2 * l2 * d), -1, 1))
    knee = np.pi - np.arccos(np.clip((l1**2 + l2**2 - d**2) / (2 * l1 * l2), -1, 1))
    shank = psi + beta
    return shank - knee, shank, knee


@dataclass(frozen=True)
class LegGeometry:
    """Sagittal lengths (m): hip -> knee, knee -> ankle, ankle above the sole, and the sole's
    heel behind and toe ahead of the ankle (the points the foot rolls about)."""

    thigh: float
    shank: float
    ankle_height: float
    heel: float = 0.0
    toe: float = 0.0


def gait_q(t: np.ndarray, ev: GaitEvents, p: GaitParams, left: LegGeometry,
           right: LegGeometry, rng: np.random.Generator) -> np.ndarray:
    """q (n, 12) of the model over times t (within the events' strides)."""
    n_str = len(ev.p_land)
    # hip x, z through double-support midpoints and mid single support
    t1 = 0.5 * (ev.p_land + ev.h_lift)
    t2 = 0.5 * (ev.h_land + ev.p_lift)
    h_prev = np.concatenate([[ev.p_print[0] - (ev.h_print[0] - ev.p_print[0])],
                             ev.h_print[:-1]])
    x1 = 0.5 * (ev.p_print + h_prev)
    x2 = 0.5 * (ev.p_print + ev.h_print)
    tk = np.ravel(np.column_stack([t1, t2]))
    xk = np.ravel(np.column_stack([x1, x2]))
    zds = p.hip_height_ds + p.sd_height * rng.standard_normal(2 * n_str)
    tm = np.ravel(np.column_stack([0.5 * (t1 + t2), 0.5 * (t2 + np.r_[t1[1:], 2 * t2[-1] -
                                                                       t1[-1]])]))
    zss = p.hip_height_ss + p.sd_height * rng.standard_normal(2 * n_str)
    tz = np.ravel(np.column_stack([tk, tm]))
    zz = np.ravel(np.column_stack([zds, zss]))
    x_hip = PchipInterpolator(tk, xk, extrapolate=True)(t)
    z_hip = PchipInterpolator(tz, zz, extrapolate=True)(t)
    phase = np.interp(t, np.r_[ev.p_land, ev.p_land[-1] + (ev.p_land[-1] - ev.p_land[-2])],
                      np.arange(n_str + 1.0))
    th_b = p.trunk_lean + p.trunk_sway * np.sin(4 * np.pi * phase)
    clr = p.clearance + p.sd_clearance * rng.standard_normal((2, n_str))
    # human foot: swing k from h_prev[k] to h_print[k]; prosthesis: p_print[k] -> p_print[k+1]
    rolls = p.heel_strike_pitch or p.toe_off_pitch
    # the human foot is flat at the prosthesis's lift-off, its heel rises before the
    # prosthesis's next touchdown; the prosthesis foot alike
    h_roll = _Roll(ev.p_lift, ev.p_land - p.heel_rise,
                   p.heel_strike_pitch, p.toe_off_pitch, left.heel, left.toe) if rolls else None
    p_roll = _Roll(ev.h_lift[1:], ev.h_land[:-1] - p.heel_rise, p.heel_strike_pitch,
                   p.toe_off_pitch, right.heel, right.toe) if rolls else None
    hx, hz, hph = _foot(t, ev.h_lift, ev.h_land, h_prev, ev.h_print, clr[0], p.toe_up_human,
                        h_roll)
    px, pz, pph = _foot(t, ev.p_lift[:-1], ev.p_land[1:], ev.p_print[:-1], ev.p_print[1:],
                        clr[1], p.toe_up_prosthesis, p_roll)
    legs = ((hx, hz, hph, left, (3, 4, 5), "left leg"),
            (px, pz, pph, right, (6, 10, 11), "right leg"))
    ankles = [np.column_stack([sx + g.ankle_height * np.sin(ph),
                               sz + g.ankle_height * np.cos(ph)]) for sx, sz, ph, g, *_ in legs]
    # the hip never rises above what both legs reach with the knee slightly bent: a smooth
    # minimum of the template height and each leg's reach (at p.max_leg_extension)
    heights = [z_hip]
    for a, (*_, g, _, name) in zip(ankles, legs, strict=True):
        reach = p.max_leg_extension * (g.thigh + g.shank)
        dx = x_hip - a[:, 0]
        if np.any(np.abs(dx) >= reach):
            raise MocapError(f"gait template: {name}: step too long for the leg")
        heights.append(a[:, 1] + np.sqrt(reach**2 - dx**2))
    k = p.height_smoothing
    hs = np.stack(heights)
    lo = hs.min(0)
    z_hip = lo - k * np.log(np.exp(-(hs - lo) / k).sum(0))
    if p.height_lowpass_hz > 0 and len(t) > 30:
        dt = float(np.median(np.diff(t)))
        sos = butter(2, p.height_lowpass_hz * 2 * dt, output="sos")
        z_hip = sosfiltfilt(sos, z_hip)
        # the filter may overshoot the reach a little: lower the whole path to fit
        hard = np.min([a[:, 1] + np.sqrt(np.maximum(
            (0.999 * (g.thigh + g.shank)) ** 2 - (x_hip - a[:, 0]) ** 2, 0.0))
            for a, (*_, g, _, _) in zip(ankles, legs, strict=True)], axis=0)
        z_hip = z_hip - max(0.0, float(np.max(z_hip - hard)))
    hip = np.column_stack([x_hip, z_hip])
    q = np.zeros((len(t), 12))
    q[:, 0], q[:, 1], q[:, 2] = x_hip, z_hip, th_b
    for ankle, (_, _, ph, g, idx, name) in zip(ankles, legs, strict=True):
        th_thigh, th_shank, knee = _two_link_ik(hip, ankle, g.thigh, g.shank, name)
        q[:, idx[0]] = th_thigh - th_b
        q[:, idx[1]] = knee
        q[:, idx[2]] = ph - th_shank
    return q
