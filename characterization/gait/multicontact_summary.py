"""A multi-contact fit and its take as :class:`~characterization.gait.person_check.WalkSummary`
(for :func:`~characterization.gait.person_check.check_person`), and each foot's ground reaction
over its stance.

The cycle starts where the fit's does (the prosthesis's single support: the human foot's
lift-off); both sides' joint angles are sampled on 0..1 of their own stride.  A foot's stance
(the prosthesis's: ds_p on its heel, ps flat, ps_toe and ds_h on its toe; the human's alike)
is its contact's wrench over those domains in order, on 0..1 of the stance; its centre of
pressure is in its sole frame's x (m): -M_y / F_z flat, the heel's or the toe's x on a point.
"""

from __future__ import annotations

import numpy as np

from characterization.gait.multicontact import (
    GRAPH,
    SIDE,
    STANCE,
    TRACKED,
    MultiContactOptions,
    MultiContactResult,
    MultiContactTargets,
    body_weight,
    handover_margins,
    sole_ends,
)
from characterization.gait.person_check import StanceForce, WalkSummary
from hp_model.domains import Domain
from hp_model.human_prosthesis import HumanProsthesisModel

#: joint-angle samples over the cycle
CYCLE_SAMPLES = 101


def _cycle(pieces: list[tuple[float, np.ndarray]], n: int = CYCLE_SAMPLES) -> np.ndarray:
    """Rows over the whole cycle from (duration, rows at evenly spaced instants) per domain,
    at ``n`` evenly spaced instants of 0..1 of the cycle."""
    t, v = [], []
    t0 = 0.0
    for T, a in pieces:
        k = a.shape[1]
        t.append(t0 + np.linspace(0.0, T, k))
        v.append(a)
        t0 += T
    tt, vv = np.concatenate(t), np.hstack(v)
    s = np.linspace(0.0, t0, n)
    return np.array([np.interp(s, tt, r) for r in vv])


def _angles(pieces: list[tuple[float, np.ndarray]]) -> dict[str, np.ndarray]:
    cyc = np.degrees(_cycle(pieces))
    return {name: cyc[i] for i, name in enumerate(TRACKED)}


def take_summary(targets: MultiContactTargets, source: str = "take",
                 grf: dict[str, StanceForce] | None = None,
                 body_weight: float = float("nan")) -> WalkSummary:
    """The take's walk as the fit saw it: speed, stride, the two double supports (after the
    human's heel strike, then the prosthesis's), the mean angles over the cycle; ``grf`` per
    foot from force plates where the take has them."""
    pieces = [(targets.durations[d], np.asarray(targets.angles[d])) for d in GRAPH.domains]
    return WalkSummary(
        speed=targets.speed, stride_time=targets.stride_time,
        double_supports=(targets.durations[Domain.DS_H], targets.durations[Domain.DS_P]),
        joint_angles=_angles(pieces), grf=grf or {}, body_weight=body_weight, source=source)


def stance_force(model: HumanProsthesisModel, result: MultiContactResult, foot: str,
                 n: int = CYCLE_SAMPLES) -> StanceForce:
    """``foot``'s ground reaction over its stance in the fitted cycle (module docstring)."""
    side = SIDE[foot]
    heel, toe = sole_ends(model, side)
    pieces = []
    for d in STANCE[foot]:
        lam = result.trajectory[d]["lam"]
        o = 0
        for c in d.contacts:
            if c.side == side:
                fx, fz = lam[o], lam[o + 1]
                if c.is_flat:
                    cop = -lam[o + 2] / np.where(np.abs(fz) > 1e-9, fz, np.nan)
                else:
                    cop = np.full_like(fz, heel if c.frame.endswith("heel") else toe)
                pivot = np.full_like(fz, 0.0 if c.is_flat else 1.0)
                if c.is_flat:  # its handovers: on the sole's ends by design
                    first, last = handover_margins(d, MultiContactOptions())
                    pivot[0], pivot[-1] = first[0] == 0.0, last[1] == 0.0
                pieces.append((result.durations[d], np.vstack([fx, fz, cop, pivot])))
            o += c.size
    fx, fz, cop, pivot = _cycle(pieces, n)
    return StanceForce(fx=fx, fz=fz, cop_x=cop, sole=(heel, toe), pivot=pivot > 0.0)


def gait_summary(model: HumanProsthesisModel, result: MultiContactResult,
                 source: str = "gait") -> WalkSummary:
    """The fitted cycle's walk: speed, stride, double supports, angles over the cycle, each
    foot's ground reaction over its stance."""
    idx = [model.coord_names.index(c) for c in TRACKED]
    pieces = [(result.durations[d], result.trajectory[d]["q"][idx]) for d in GRAPH.domains]
    return WalkSummary(
        speed=result.speed, stride_time=result.stride_time,
        double_supports=(result.durations[Domain.DS_H], result.durations[Domain.DS_P]),
        joint_angles=_angles(pieces),
        grf={f: stance_force(model, result, f) for f in STANCE},
        body_weight=body_weight(model),
        source=source)
