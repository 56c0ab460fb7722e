"""A simulated person whose pace varies from stride to stride, as a person's does (stride-time
variability of about 2-3 % coefficient of variation in healthy walking; Hausdorff,
Human Movement Science 26, 2007): a gait schedule (:data:`hp_model.simulator.GaitSchedule`)
over the person's curves.

At each entry into its own flat stance (``pns``: where the person holds its hip's rate), the
person draws a pace factor exp(N(0, cv)) and walks the stride from there with its hip-rate
curves V(tau) and v_hip times that factor in every domain that has one (its joints follow
the hip's progress, so the whole person walks faster or slower; the toe domains' pace is
their zero dynamics').  Drawn there, the oracle prosthesis walked 20 of 20 draws at 3 % on
the packaged person; drawn at the human's heel strike (``ds_h``) 16, at the prosthesis's
(``ds_p``) 16: a change of the hip's rate at an impact, where the feet's forces are
settling, pulled a foot off the ground.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from hp_model.domains import Domain
from hp_model.outputs import ThetaLayout
from hp_model.simulator import GaitSchedule

#: where the person draws its next stride's pace
PACE_DOMAIN = Domain.PNS


def paced_theta(d: Domain, theta: np.ndarray, factor: float, degree: int) -> np.ndarray:
    """Domain ``d``'s packed curves with its hip-rate curve and v_hip times ``factor`` (the
    same curves where ``d`` has no velocity output)."""
    out = np.array(theta, dtype=float, copy=True)
    if d.velocity_output:
        lay = ThetaLayout(degree, (out.size - 3) // (degree + 1))
        out[lay.row(len(d.y2_coords))] *= factor  # the hip rate's row follows the joints'
        out[lay.v_hip] *= factor
    return out


def varying_pace(thetas: Mapping[Domain, np.ndarray], cv: float, seed: int, degree: int
                 ) -> GaitSchedule:
    """The person of the module docstring walking ``thetas`` (packed curves per domain, of
    Bezier ``degree``), its pace's coefficient of variation ``cv`` from stride to stride,
    its draws from ``seed``; the first stride at the curves' own pace."""
    if not (np.isfinite(cv) and 0.0 <= cv < 0.5):
        raise ValueError(f"a stride's pace variation must be within 0-0.5, got {cv}")
    rng = np.random.default_rng(seed)
    base = {Domain(d): np.asarray(th, float) for d, th in thetas.items()}
    factor = 1.0

    def gait(d: Domain, t: float) -> np.ndarray:
        nonlocal factor
        if d == PACE_DOMAIN and t > 0.0:
            factor = float(np.exp(rng.normal(0.0, cv)))
        return paced_theta(d, base[d], factor, degree)

    return gait
