"""The multi-contact controllers as a file: what :class:`ContactClfQp` (``clfqp``) and its
phase law :class:`ContactPhasePD` follow, made once from a gait (its stance as the model
walks it: ``orchestrator.cosim.contact_controllers``) and loaded by the controller process,
which cannot walk the model itself.

Layout (``numpy.savez``, no pickles; SI units, rad):

    meta            JSON: kind ``hpcosim-contact-controller``, schema_version 3; the model
                    (subject, device: the leg's geometry the phase is sensed with) and its
                    hash; the gait's hash; the phase law's progress (m), swing time (s), flat
                    stance phases, gains (joint N m/rad, N m s/rad), the swing phase's measure
                    (``time`` or ``thigh``), gear ratios, motor
                    limits (N m); the CLF-QP's constants (:class:`ContactClfConfig`)
    stance.phase, stance.values, swing.phase, swing.values
                    the phase law's tables (:class:`PhaseTable`)
    swing.pitch     the socket's world pitch at swing.phase (the swing phase's measure,
                    :class:`~prosthesis_controller.thigh_phase.ThighSwingPhase`)
    qp.phase, qp.domain (Domain.code), qp.g, qp.u_ref, qp.qdd_ref, qp.P, qp.c, qp.G, qp.h,
    qp.d_center, qp.d_radius
                    the stance QP's per-sample data (:class:`StanceQp`; the last two the
                    robust term's box, zero without a model-error bound)

Older schemas (1: no qdd_ref, no robust term; 2: no swing pitch) are refused: the file is a
cache, made again from the gait.
"""

from __future__ import annotations

import io
import json
import os
from dataclasses import asdict
from pathlib import Path
from typing import Any

import numpy as np

from hp_model.artifacts import ArtifactError
from hp_model.atomic_io import atomic_write_bytes
from hp_model.config import DeviceConfig, SubjectConfig
from hp_model.domains import Domain, DomainGraph
from hp_model.human_prosthesis import HumanProsthesisModel
from hp_model.json_io import dumps
from hp_model.leg_kinematics import LegKinematics
from prosthesis_controller.contact_clf_qp import ContactClfConfig, ContactClfQp, StanceQp
from prosthesis_controller.contact_phase_pd import (
    ContactGaitTables,
    ContactPhasePD,
    PDGains,
    PhaseTable,
)

KIND = "hpcosim-contact-controller"
SCHEMA_VERSION = 3  # 3: the swing's thigh pitch (the swing phase's measure)
_QP = ("phase", "g", "u_ref", "qdd_ref", "P", "c", "G", "h", "d_center", "d_radius")


def save_contact_controller(path: str | os.PathLike[str], ctl: ContactClfQp,
                            model: HumanProsthesisModel, gait_hash: str) -> None:
    """Write ``ctl`` (made for ``model`` and the gait of hash ``gait_hash``) atomically."""
    law, tab, qp = ctl.law, ctl.law.tables, ctl.stance
    meta = {"kind": KIND, "schema_version": SCHEMA_VERSION,
            "model_hash": model.parameter_hash(), "gait_hash": gait_hash,
            "subject": model.subject.model_dump(mode="json"),
            "device": model.device.model_dump(mode="json"),
            "progress": list(tab.progress), "swing_time": tab.swing_time,
            "flat": list(tab.flat),
            "stance_gains": asdict(law.stance_gains), "swing_gains": asdict(law.swing_gains),
            "swing_phase": law.swing_phase,
            "gear": list(law.gear), "limits": list(law.limits), "config": asdict(ctl.config)}
    arrays: dict[str, Any] = {
        "meta": np.array(dumps(meta)),
        "stance.phase": tab.stance.phase, "stance.values": tab.stance.values,
        "swing.phase": tab.swing.phase, "swing.values": tab.swing.values,
        "swing.pitch": tab.swing_pitch,
        "qp.domain": np.array([d.code for d in qp.domain]),
        **{f"qp.{k}": getattr(qp, k) for k in _QP}}
    buf = io.BytesIO()
    np.savez(buf, **arrays)
    atomic_write_bytes(path, buf.getvalue())


def _gains(meta: dict[str, Any], key: str) -> PDGains:
    g = meta[key]
    return PDGains((float(g["kp"][0]), float(g["kp"][1])), (float(g["kd"][0]), float(g["kd"][1])))


def load_contact_controller(path: str | os.PathLike[str], model_hash: str | None = None
                            ) -> tuple[ContactClfQp, HumanProsthesisModel]:
    """The controller of the file and the model it was made for (ArtifactError naming the
    file and field when it is not such a file, or, with ``model_hash``, made for another
    model)."""
    src = str(path)
    try:
        with np.load(Path(path), allow_pickle=False) as z:
            data = {k: z[k] for k in z.files}
    except (OSError, ValueError, EOFError) as e:
        raise ArtifactError(f"{src}: not a controller file ({e})") from None
    try:
        meta = json.loads(str(data.pop("meta")))
    except (KeyError, ValueError) as e:
        raise ArtifactError(f"{src}: field 'meta': missing or not JSON ({e})") from None
    if meta.get("kind") != KIND or meta.get("schema_version") != SCHEMA_VERSION:
        raise ArtifactError(f"{src}: field 'kind': not a multi-contact controller file of "
                            f"version {SCHEMA_VERSION} ({meta.get('kind')!r}, "
                            f"{meta.get('schema_version')!r})")
    if model_hash is not None and meta.get("model_hash") != model_hash:
        raise ArtifactError(f"{src}: field 'model_hash': made for another model "
                            f"({meta.get('model_hash')}, not {model_hash})")
    field = "meta"
    try:
        model = HumanProsthesisModel(SubjectConfig.model_validate(meta["subject"]),
                                     DeviceConfig.model_validate(meta["device"]),
                                     graph=DomainGraph.MULTICONTACT)
        if model.parameter_hash() != meta["model_hash"]:
            raise ValueError("its subject and device give another model than its model_hash")
        tables = ContactGaitTables(
            PhaseTable(data["stance.phase"], data["stance.values"]),
            PhaseTable(data["swing.phase"], data["swing.values"]),
            (float(meta["progress"][0]), float(meta["progress"][1])),
            float(meta["swing_time"]), (float(meta["flat"][0]), float(meta["flat"][1])),
            np.asarray(data["swing.pitch"], float))
        law = ContactPhasePD(tables, LegKinematics.of(model),
                             (float(meta["gear"][0]), float(meta["gear"][1])),
                             (float(meta["limits"][0]), float(meta["limits"][1])),
                             _gains(meta, "stance_gains"), _gains(meta, "swing_gains"),
                             str(meta["swing_phase"]))
        field = "qp"
        stance = StanceQp(domain=tuple(Domain.from_code(int(c)) for c in data["qp.domain"]),
                          **{k: np.asarray(data[f"qp.{k}"], float) for k in _QP})
        config = ContactClfConfig(**meta["config"])
    except (KeyError, TypeError, ValueError) as e:
        raise ArtifactError(f"{src}: field '{field}': {e}") from None
    return ContactClfQp(law, stance, law.limits, config), model


__all__ = ["KIND", "SCHEMA_VERSION", "load_contact_controller", "save_contact_controller"]
