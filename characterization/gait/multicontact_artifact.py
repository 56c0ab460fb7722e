"""The multi-contact gait artifact: the person's fitted cycle (:mod:`.multicontact`) as a
versioned JSON file.

Layout (``kind = "hpcosim-gait-multicontact"``, ``schema_version = 1``; SI units, rad):

    model_hash       hash of the model parameters (subject, device, graph) it was made for
    domain_graph     "multicontact"; ``domains`` in walking order
    stride           {length m, time s, speed m/s}
    trajectory.<d>   per domain: {duration, t (P,), q, qd, qdd (12, P), u (6, P),
                     lam (n_c, P): the contacts' wrenches in Domain.contacts order, then the
                     socket's (N, N m)}
    ground_reaction  per foot (human, prosthesis): its stance on 0..1 {fx, fz (N), cop_x (m,
                     sole frame), pivot (on its heel or toe point), sole (heel end, toe end)}
    targets          what the take gave the fit: {durations per domain, speed}
    check            the comparison with the take (:mod:`.person_check`), its verdict
    mismatch_allowed true when written by ``--allow-mismatch`` although not the person's
    options, solver  the fit's settings; IPOPT's status, iterations, seconds, cost, and how its
                     last (jerk) stage ended
    subject, device  the model's configs (``gait fit`` cuts the device's pylon to the person's
                     leg unless given ``--device``), so the file remakes its model
"""

from __future__ import annotations

import os
from dataclasses import asdict, dataclass, fields
from typing import Any

import numpy as np

from characterization.gait.multicontact import (
    GRAPH,
    MultiContactError,
    MultiContactOptions,
    MultiContactResult,
    MultiContactTargets,
)
from characterization.gait.person_check import PersonCheck, StanceForce
from hp_model.artifacts import ArtifactError, canonical_hash, load_json, save_json
from hp_model.domains import Domain
from hp_model.gait_artifact import MULTICONTACT_KIND
from hp_model.human_prosthesis import HumanProsthesisModel

KIND = MULTICONTACT_KIND
SCHEMA_VERSION = 1


def _force_doc(s: StanceForce) -> dict[str, Any]:
    return {"fx": s.fx, "fz": s.fz, "cop_x": s.cop_x, "sole": s.sole,
            "pivot": None if s.pivot is None else np.asarray(s.pivot, bool).tolist()}


def to_document(result: MultiContactResult, targets: MultiContactTargets,
                grf: dict[str, StanceForce], check: PersonCheck, model_hash: str,
                options: MultiContactOptions, mismatch_allowed: bool = False
                ) -> dict[str, Any]:
    """The artifact's JSON document (module docstring)."""
    traj = {d.value: {"duration": result.durations[d], **result.trajectory[d]}
            for d in GRAPH.domains}
    return {
        "kind": KIND, "schema_version": SCHEMA_VERSION, "model_hash": model_hash,
        "domain_graph": GRAPH.value, "domains": [d.value for d in GRAPH.domains],
        "stride": {"length": result.stride_length, "time": result.stride_time,
                   "speed": result.speed},
        "trajectory": traj,
        "ground_reaction": {foot: _force_doc(s) for foot, s in grf.items()},
        "targets": {"durations": {d.value: targets.durations[d] for d in GRAPH.domains},
                    "speed": targets.speed,
                    "flat_foot_pitch": dict(targets.flat_foot_pitch)},
        "check": check.to_json(),
        "mismatch_allowed": bool(mismatch_allowed),
        "options": asdict(options),
        "solver": {"status": result.status, "success": result.success,
                   "iterations": result.iterations, "seconds": result.solve_seconds,
                   "cost": result.cost, "jerk_stage": result.stats.get("jerk_stage"),
                   "angle_limit_stage": result.stats.get("angle_limit_stage")},
    }


def save_multicontact_gait(path: str | os.PathLike[str], doc: dict[str, Any]) -> None:
    """Write the document atomically (strict JSON: non-finite numbers as null)."""
    save_json(path, doc)


def fit_options(doc: dict[str, Any], path: str | os.PathLike[str] = "gait") -> MultiContactOptions:
    """The fit's settings a gait document records (``options``; ArtifactError naming the
    file and field when they are not the fit's)."""
    known = {f.name for f in fields(MultiContactOptions)}
    try:
        kw: dict[str, Any] = {k: tuple(v) if isinstance(v, list) else v
                              for k, v in doc["options"].items() if k in known}
        return MultiContactOptions(**kw)
    except (KeyError, TypeError, AttributeError, MultiContactError) as e:
        raise ArtifactError(f"{path}: field 'options': {e}") from None


def load_multicontact_gait(path: str | os.PathLike[str]) -> dict[str, Any]:
    """The document of a multi-contact gait file (:class:`~hp_model.artifacts.ArtifactError`
    naming the file and field when it is not one)."""
    return dict(load_json(path, KIND, SCHEMA_VERSION))


@dataclass(frozen=True)
class ContactCycle:
    """A multi-contact gait file read back: the model it was made for (its subject, device
    and the graph), the fitted cycle's per-domain trajectories (``t``, ``q``, ``qd``, ``qdd``,
    ``u``, ``lam``) and durations (s)."""

    model: HumanProsthesisModel
    trajectory: dict[Domain, dict[str, np.ndarray]]
    durations: dict[Domain, float]
    #: the file's identity: the hash of its model and its cycle (what a tube fitted around
    #: this gait records)
    hash: str = ""


def model_of(doc: dict[str, Any], path: str | os.PathLike[str]) -> HumanProsthesisModel:
    """The multi-contact model a document's ``subject`` and ``device`` make (ArtifactError
    naming the file and field when they are not valid configs)."""
    from pydantic import ValidationError

    from hp_model.config import DeviceConfig, SubjectConfig

    try:
        subject = SubjectConfig.model_validate(doc["subject"])
        device = DeviceConfig.model_validate(doc["device"])
    except (KeyError, ValidationError) as e:
        raise ArtifactError(f"{path}: field 'subject'/'device': not a valid config "
                            f"({str(e).splitlines()[0]})") from None
    return HumanProsthesisModel(subject, device, graph=GRAPH)


def load_contact_cycle(path: str | os.PathLike[str]) -> ContactCycle:
    """The model and the cycle of a multi-contact gait file (ArtifactError naming the file
    and field when it is not one, or its configs are not valid)."""
    doc = load_multicontact_gait(path)
    model = model_of(doc, path)
    try:
        traj = {d: {k: np.asarray(v, float) for k, v in doc["trajectory"][d.value].items()
                    if k != "duration"} for d in GRAPH.domains}
        durations = {d: float(doc["trajectory"][d.value]["duration"]) for d in GRAPH.domains}
    except (KeyError, TypeError, ValueError) as e:
        raise ArtifactError(f"{path}: field 'trajectory': {e}") from None
    if doc.get("model_hash") not in (None, model.parameter_hash()):
        raise ArtifactError(f"{path}: field 'model_hash': the file was made for another "
                            "model than its own subject and device give")
    ident = canonical_hash({"model_hash": model.parameter_hash(),
                            "trajectory": doc["trajectory"]})
    return ContactCycle(model, traj, durations, ident)

