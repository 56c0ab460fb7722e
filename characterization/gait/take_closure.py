"""How far a take's joint angles are from a posture the model's rigid legs can hold in double
support: through the model's frames, each double support's leading heel and trailing toe
should sit on one ground line; a marker-based take's seldom do (skin on the thighs, joint
centres, segment lengths).  The fit must then change the angles to put both feet down, so
this gap bounds how close to the take its gait can be (docs/gait-design.md, "Where the
ankles' error comes from")."""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import casadi as ca
import numpy as np

from characterization.gait.multicontact import GRAPH, TRACKED, TakeStrides
from hp_model.human_prosthesis import HumanProsthesisModel


@dataclass(frozen=True)
class DoubleSupportClosure:
    """One double support of the take, over its frames in the complete strides.

    ``gap_mm``: mean height of the leading heel above the trailing toe (mm) with the take's
    angles through the model's frames; 0 where the legs close.  ``least_change_deg``: RMS
    over the frames of the smallest change of the tracked angles (their Euclidean norm, deg)
    that puts both on one ground line (the base's height free)."""

    domain: str
    frames: int
    gap_mm: float
    least_change_deg: float

    def to_json(self) -> dict[str, float | int | str]:
        return asdict(self)


def double_support_closure(model: HumanProsthesisModel, strides: TakeStrides
                           ) -> tuple[DoubleSupportClosure, ...]:
    """Each double support's closure (:class:`DoubleSupportClosure`) from the take's strides
    (:func:`characterization.gait.multicontact.take_strides`, its ankles calibrated to the
    model's flat sole); frames with an unknown angle are left out."""
    names = list(model.coord_names)
    tracked = [names.index(c) for c in TRACKED]
    out = []
    for d in GRAPH.domains:
        if not d.is_double_support:
            continue
        lead, trail = (model.frame_expr(c.frame)[1] for c in d.contacts)  # heel, then toe
        gap = ca.Function("gap", [model.q], [lead - trail, ca.gradient(lead - trail, model.q)])
        gaps, changes = [], []
        for w in strides.windows:
            a, b = w[d]
            for q in strides.q[a:b + 1]:
                if not np.all(np.isfinite(q)):
                    continue
                r, grad = (np.asarray(v, float).ravel() for v in gap(q))
                gaps.append(r[0])
                # one equation in the angles: its least-norm solution's size is |r| / |grad|
                changes.append(abs(r[0]) / max(float(np.linalg.norm(grad[tracked])), 1e-9))
        if gaps:
            out.append(DoubleSupportClosure(
                d.value, len(gaps), 1000.0 * float(np.mean(gaps)),
                math.degrees(float(np.sqrt(np.mean(np.square(changes)))))))
    return tuple(out)


def closure_line(closures: tuple[DoubleSupportClosure, ...]) -> str:
    """One line for ``gait fit``'s output."""
    parts = [f"{c.domain} {c.gap_mm:+.0f} mm (angles' least change {c.least_change_deg:.1f} "
             "deg)" for c in closures]
    return ("take: through the model's legs, each double support's leading heel sits above "
            "its trailing toe by " + ", ".join(parts) + ": what the fit must change to put "
            "both feet down (0 where the legs close; a static trial's leg landmarks take out "
            "a standing lean, docs/recording.md; docs/gait-design.md)")
