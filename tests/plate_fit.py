"""The multi-contact fit of a steps file with force plates, compared with the take as
``gait fit`` compares it (the closed-loop walks left out): shared by the real takes' tests."""

from __future__ import annotations

from characterization.gait.contact_gait import ContactWalk
from characterization.gait.multicontact import (
    GRAPH,
    MultiContactOptions,
    MultiContactResult,
    fit_multicontact,
    targets_from_steps,
)
from characterization.gait.multicontact_summary import gait_summary, take_summary
from characterization.gait.person_check import PersonCheck, StanceForce, check_person
from characterization.mocap.steps_artifact import StepsArtifact, plate_forces, steps_subject
from hp_model.human_prosthesis import HumanProsthesisModel


def worn_model(steps: StepsArtifact, src: str = "steps") -> HumanProsthesisModel:
    """The steps' subject on the device they would wear: what `gait fit` uses."""
    from characterization.gait.fit import worn_device
    from hp_model.config import default_device_path, load_device

    person, _ = steps_subject(steps, src)
    device, _ = worn_device(person, load_device(default_device_path()))
    return HumanProsthesisModel(person, device, graph=GRAPH)


def fit_against_plates(steps: StepsArtifact, model: HumanProsthesisModel) -> PersonCheck:
    """The fit with default options (asserted converged), compared with the take and its
    plates."""
    return _fitted(steps, model)[0]


def fit_walks_on_clfqp(steps: StepsArtifact, model: HumanProsthesisModel
                       ) -> tuple[PersonCheck, ContactWalk]:
    """The comparison of :func:`fit_against_plates` and the fitted cycle walked 10 steps with
    the prosthesis on ``clfqp`` (the human on the fitted gait): `gait fit`'s verdict."""
    from characterization.gait.contact_gait import contact_gait
    from orchestrator.experiments.contact_walk import walk_with_contact_clfqp

    check, result = _fitted(steps, model)
    walk = walk_with_contact_clfqp(model, contact_gait(model, result), result.trajectory, 10)
    return check, walk


def _fitted(steps: StepsArtifact, model: HumanProsthesisModel
            ) -> tuple[PersonCheck, MultiContactResult]:
    """The fit (asserted converged) and its comparison with the take and its plates."""
    t = targets_from_steps(steps, model)
    result = fit_multicontact(model, t, MultiContactOptions())
    assert result.success, result.status
    plates = plate_forces(steps)
    assert plates is not None, "the steps have no plates"
    grf, weight = plates
    take = take_summary(t, "take", {f: StanceForce(fx=m.fx, fz=m.fz) for f, m in grf.items()},
                        weight)
    return check_person(take, gait_summary(model, result)), result
