"""What the multi-contact ``clfqp``'s model does not explain, characterised offline from the
force tube's playback, and its bound: the robust term of the controller's CLF row.

:class:`prosthesis_controller.contact_clf_qp.ContactClfQp` models the prosthesis joints'
accelerations in stance linearized about the gait as the model walks it, at its stance phase
s (the hip's progress over the heel, from its own sensors):

    qdd_p = qdd_ref(s) + g(s) (u - u_ref(s))        rad/s^2, (knee, ankle)

Along a played-back flat prosthesis single support
(:mod:`characterization.tube.contact_playback`: the full model, every joint on the recorded
stride's curves) the true accelerations follow from the constrained dynamics ``dyn_ps`` at
the logged state and torques, and the model error is

    d = qdd_true - qdd_ref(s) - g(s) (u - u_ref(s))

at the controller's stance phase of each logged posture (its own progress bounds).  On the
gait's own walk d is the linearization's rest; on a recorded stride it is what the person does
differently (their speed, their posture, their timing).

The bound: per joint, the force tube's two LPs (:func:`characterization.tube.model_error.
fit_model_error`, its credibility the same) over the tube's phase range, at the tube's
degree.  No time is excluded: the flat single support starts 100 ms or more after the heel
strike, whose transient the paper graph's bound leaves out.
"""

from __future__ import annotations

import bisect
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from characterization.tube.model_error import ErrorSamples, fit_model_error
from hp_model.domains import PROSTHESIS
from hp_model.force_tube import CONTACT_ERROR_COMPONENTS, ModelErrorBound
from hp_model.human_prosthesis import HumanProsthesisModel
from hp_model.leg_kinematics import LegKinematics


@dataclass(frozen=True)
class Linearization:
    """The controller's model along its stance (its ``StanceQp``'s samples): ``phase`` (n,)
    non-decreasing, ``g`` (n, 2, 2) rad/s^2 per motor N m, ``u_ref`` (n, 2) N m, ``qdd_ref``
    (n, 2) rad/s^2; ``progress`` (m) the hip's progress at its stance phase 0 and 1."""

    phase: np.ndarray
    g: np.ndarray
    u_ref: np.ndarray
    qdd_ref: np.ndarray
    progress: tuple[float, float]

    def index(self, s: float) -> int:
        """The sample at or before phase ``s`` (the controller's rule)."""
        return min(max(bisect.bisect_right(self.phase.tolist(), s) - 1, 0), len(self.phase) - 1)


def error_samples(model: HumanProsthesisModel, lin: Linearization, playbacks: Sequence[Any]
                  ) -> list[ErrorSamples]:
    """d (module docstring) along each played-back single support (``playbacks``:
    :class:`~characterization.tube.contact_playback.StancePlayback`, their ``t``, ``q``,
    ``qd``, ``u``), at the controller's stance phase."""
    from characterization.tube.contact_playback import stance_phase

    dyn = model.numeric()["dyn_ps"]
    joints = [model.coord_names.index(c) for c in PROSTHESIS]
    leg = LegKinematics.of(model)
    out = []
    for sp in playbacks:
        phase = stance_phase(leg, model, sp.q, lin.progress)
        d = np.empty((len(phase), 2))
        for j, s in enumerate(phase):
            qdd = np.asarray(dyn(sp.q[j], sp.qd[j], sp.u[j])[0]).ravel()[joints]
            i = lin.index(float(s))
            d[j] = qdd - lin.qdd_ref[i] - lin.g[i] @ (sp.u[j, 4:6] - lin.u_ref[i])
        out.append(ErrorSamples(np.asarray(phase, float), sp.t - sp.t[0], d))
    return out


def fit_contact_model_error(model: HumanProsthesisModel, lin: Linearization,
                            playbacks: Sequence[Any], degree: int, within: tuple[float, float],
                            source: dict[str, Any] | None = None) -> ModelErrorBound:
    """The bound of d over the phase range ``within`` (the tube's) at ``degree``
    (:class:`~characterization.tube.fit.TubeFitError` when the samples cannot give one)."""
    samples = error_samples(model, lin, playbacks)
    return fit_model_error(samples, degree, exclude_after_touchdown=0.0, within=within,
                           components=CONTACT_ERROR_COMPONENTS,
                           source={**(source or {}), "model": "the multi-contact clfqp's: "
                                   "qdd_ref + g (u - u_ref) at its stance phase",
                                   "phase": "the prosthesis controllers' stance phase"})
