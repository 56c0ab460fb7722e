"""The multi-contact controllers as a file: what :class:`ContactClfQp` (``clfqp``), its
phase law :class:`ContactPhasePD` (``phase-pd``) and the paper's baselines on the graph
(:class:`~prosthesis_controller.pd.ContactJointPD`, ``pd``;
:class:`~prosthesis_controller.passive.ContactPassive`, ``passive``) follow, made once from a
gait (its stance as the model walks it: ``orchestrator.cosim.contact_controllers``) and
loaded by the controller process, which cannot walk the model itself.

Layout (``numpy.savez``, no pickles; SI units, rad):

    meta            JSON: kind ``hpcosim-contact-controller``, schema_version 5; the law
                    (``law``: one of :data:`LAWS`); the model
                    (subject, device: the leg's geometry the phase is sensed with) and its
                    hash; the gait's hash; the phase law's progress (m), swing time (s), flat
                    stance phases, gains (joint N m/rad, N m s/rad), the swing phase's measure
                    (``time`` or ``thigh``), gear ratios, motor
                    limits (N m); ``clfqp``: the CLF-QP's constants
                    (:class:`ContactClfConfig`); ``passive``: its gains
                    (:class:`~prosthesis_controller.config.PassiveConfig`)
    stance.phase, stance.values, swing.phase, swing.values
                    the phase law's tables (:class:`PhaseTable`)
    stance.accel    ``passive``: the stance's reference accelerations (rad/s^2) at
                    stance.phase
    swing.pitch     the socket's world pitch at swing.phase (the swing phase's measure,
                    :class:`~prosthesis_controller.thigh_phase.ThighSwingPhase`)
    qp.phase, qp.domain (Domain.code), qp.g, qp.u_ref, qp.qdd_ref, qp.P, qp.c, qp.G, qp.h,
    qp.d_center, qp.d_radius
                    ``clfqp``: the stance QP's per-sample data (:class:`StanceQp`; the last
                    two the robust term's box, zero without a model-error bound)

Older schemas (1: no qdd_ref, no robust term; 2: no swing pitch; 3: no load rows; 4:
``clfqp`` alone) are refused: the file is a cache, made again from the gait.

A controller following the person's speed over a gait library
(:class:`~prosthesis_controller.speed_following.SpeedFollowing`) has its own kind,
``hpcosim-speed-following-controller`` (schema 3; ``clfqp``'s): the model as above, the
library's hash, its speeds (m/s), the resolution of the controllers switched between (m/s),
the estimate's calibration (``rate_speeds``, ``rates``, m/s) and per library speed i a
controller's meta (``controllers``) with its arrays under ``c<i>.`` (``c0.stance.phase``,
...).  The controllers between the library's speeds are blended from these when loaded, as
in process.
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
from prosthesis_controller.config import PassiveConfig
from prosthesis_controller.contact_clf_qp import ContactClfConfig, ContactClfQp, StanceQp
from prosthesis_controller.contact_phase_pd import (
    ContactGaitTables,
    ContactPhasePD,
    PDGains,
    PhaseTable,
)
from prosthesis_controller.interface import ControllerName
from prosthesis_controller.passive import ContactPassive, PassiveLaw
from prosthesis_controller.pd import ContactJointPD
from prosthesis_controller.speed_following import FollowingSetup, SpeedFollowing

KIND = "hpcosim-contact-controller"
SCHEMA_VERSION = 5  # 3: the swing's thigh pitch (the swing phase's measure); 4: the load rows;
#                     5: the law (clfqp or one of the baselines)
#: the laws a controller file holds (their ``--controller`` words)
LAWS = (ControllerName.CLFQP.value, ControllerName.PHASE_PD.value, ControllerName.PD.value,
        ControllerName.PASSIVE.value)
#: a file's law, a multi-contact controller's
ContactController = ContactClfQp | ContactPhasePD
#: a speed-following controller's file (:class:`FollowingSetup`): the controllers at a gait
#: library's speeds, each under its own prefix ``c<i>.`` as above, and the estimate's
#: calibration
FOLLOWING_KIND = "hpcosim-speed-following-controller"
FOLLOWING_SCHEMA_VERSION = 3  # 2: its controllers' load rows; 3: their law
_QP = ("phase", "g", "u_ref", "qdd_ref", "P", "c", "G", "h", "d_center", "d_radius", "load_ref",
       "load_gain", "load_h")


def _model_meta(model: HumanProsthesisModel) -> dict[str, Any]:
    return {"model_hash": model.parameter_hash(),
            "subject": model.subject.model_dump(mode="json"),
            "device": model.device.model_dump(mode="json")}


def law_of(ctl: ContactController) -> str:
    """The law of a multi-contact controller (one of :data:`LAWS`)."""
    if isinstance(ctl, ContactClfQp):
        return ControllerName.CLFQP.value
    if isinstance(ctl, ContactJointPD):
        return ControllerName.PD.value
    if isinstance(ctl, ContactPassive):
        return ControllerName.PASSIVE.value
    return ControllerName.PHASE_PD.value


def _controller_parts(ctl: ContactController, prefix: str = ""
                      ) -> tuple[dict[str, Any], dict[str, Any]]:
    """The meta (JSON) and the arrays (named under ``prefix``) of one controller."""
    law = ctl.law if isinstance(ctl, ContactClfQp) else ctl
    tab = law.tables
    meta = {"law": law_of(ctl), "progress": list(tab.progress), "swing_time": tab.swing_time,
            "flat": list(tab.flat),
            "stance_gains": asdict(law.stance_gains), "swing_gains": asdict(law.swing_gains),
            "swing_phase": law.swing_phase,
            "gear": list(law.gear), "limits": list(law.limits)}
    arrays: dict[str, Any] = {
        "stance.phase": tab.stance.phase, "stance.values": tab.stance.values,
        "swing.phase": tab.swing.phase, "swing.values": tab.swing.values,
        "swing.pitch": tab.swing_pitch}
    if isinstance(ctl, ContactClfQp):
        qp = ctl.stance
        meta["config"] = asdict(ctl.config)
        arrays["qp.domain"] = np.array([d.code for d in qp.domain])
        arrays.update({f"qp.{k}": getattr(qp, k) for k in _QP})
    if isinstance(ctl, ContactPassive):
        meta["passive"] = ctl.law.config.model_dump(mode="json")
        arrays["stance.accel"] = ctl.accel.values
    return meta, {prefix + k: v for k, v in arrays.items()}


def _write(path: str | os.PathLike[str], meta: dict[str, Any], arrays: dict[str, Any]) -> None:
    buf = io.BytesIO()
    np.savez(buf, meta=np.array(dumps(meta)), **arrays)
    atomic_write_bytes(path, buf.getvalue())


def save_contact_controller(path: str | os.PathLike[str], ctl: ContactController,
                            model: HumanProsthesisModel, gait_hash: str) -> None:
    """Write ``ctl`` (made for ``model`` and the gait of hash ``gait_hash``) atomically."""
    meta, arrays = _controller_parts(ctl)
    _write(path, {"kind": KIND, "schema_version": SCHEMA_VERSION, **_model_meta(model),
                  "gait_hash": gait_hash, **meta}, arrays)


def save_speed_following(path: str | os.PathLike[str], setup: FollowingSetup,
                         model: HumanProsthesisModel, library_hash: str) -> None:
    """Write ``setup`` (its controllers ``clfqp``'s, made for ``model`` from the gait library
    of hash ``library_hash``) atomically."""
    metas: list[dict[str, Any]] = []
    arrays: dict[str, Any] = {}
    for i, c in enumerate(setup.controllers):
        if not isinstance(c, ContactClfQp):
            raise TypeError(f"controller {i}: a file holds clfqp controllers, not "
                            f"{type(c).__name__}")
        m, a = _controller_parts(c, f"c{i}.")
        metas.append(m)
        arrays.update(a)
    _write(path, {"kind": FOLLOWING_KIND, "schema_version": FOLLOWING_SCHEMA_VERSION,
                  **_model_meta(model), "library_hash": library_hash,
                  "speeds": list(setup.speeds), "resolution": setup.resolution,
                  "rate_speeds": list(setup.rate_speeds), "rates": list(setup.rates),
                  "controllers": metas}, arrays)


def _gains(meta: dict[str, Any], key: str) -> PDGains:
    g = meta[key]
    return PDGains((float(g["kp"][0]), float(g["kp"][1])), (float(g["kd"][0]), float(g["kd"][1])))


def _read(path: str | os.PathLike[str]) -> tuple[dict[str, Any], dict[str, Any]]:
    """The meta and the arrays of a controller file (ArtifactError naming it)."""
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
    if not isinstance(meta, dict):
        raise ArtifactError(f"{src}: field 'meta': not a JSON object")
    return meta, data


def _model(src: str, meta: dict[str, Any], model_hash: str | None) -> HumanProsthesisModel:
    if model_hash is not None and meta.get("model_hash") != model_hash:
        raise ArtifactError(f"{src}: field 'model_hash': made for another model "
                            f"({meta.get('model_hash')}, not {model_hash})")
    try:
        model = HumanProsthesisModel(SubjectConfig.model_validate(meta["subject"]),
                                     DeviceConfig.model_validate(meta["device"]),
                                     graph=DomainGraph.MULTICONTACT)
        if model.parameter_hash() != meta["model_hash"]:
            raise ValueError("its subject and device give another model than its model_hash")
    except (KeyError, TypeError, ValueError) as e:
        raise ArtifactError(f"{src}: field 'meta': {e}") from None
    return model


def _controller(src: str, meta: dict[str, Any], data: dict[str, Any], model: HumanProsthesisModel,
                prefix: str = "") -> ContactController:
    """The controller of ``meta`` and the arrays under ``prefix`` (ArtifactError naming the
    field)."""
    field = f"{prefix}meta" if prefix else "meta"
    try:
        law = str(meta["law"])
        if law not in LAWS:
            raise ValueError(f"law {law!r}: expected one of {', '.join(LAWS)}")
        tables = ContactGaitTables(
            PhaseTable(data[f"{prefix}stance.phase"], data[f"{prefix}stance.values"]),
            PhaseTable(data[f"{prefix}swing.phase"], data[f"{prefix}swing.values"]),
            (float(meta["progress"][0]), float(meta["progress"][1])),
            float(meta["swing_time"]), (float(meta["flat"][0]), float(meta["flat"][1])),
            np.asarray(data[f"{prefix}swing.pitch"], float))
        leg = LegKinematics.of(model)
        gear = (float(meta["gear"][0]), float(meta["gear"][1]))
        limits = (float(meta["limits"][0]), float(meta["limits"][1]))
        stance_gains, swing_gains = _gains(meta, "stance_gains"), _gains(meta, "swing_gains")
        swing_phase = str(meta["swing_phase"])
        if law == ControllerName.PD.value:
            return ContactJointPD(tables, leg, gear, limits, stance_gains, swing_gains,
                                  swing_phase)
        if law == ControllerName.PASSIVE.value:
            accel = PhaseTable(tables.stance.phase,
                               np.asarray(data[f"{prefix}stance.accel"], float))
            return ContactPassive(tables, leg, gear, limits,
                                  PassiveLaw(model, PassiveConfig(**meta["passive"])), accel,
                                  swing_gains, swing_phase)
        phase_law = ContactPhasePD(tables, leg, gear, limits, stance_gains, swing_gains,
                                   swing_phase)
        if law == ControllerName.PHASE_PD.value:
            return phase_law
        field = f"{prefix}qp"
        stance = StanceQp(domain=tuple(Domain.from_code(int(c))
                                       for c in data[f"{prefix}qp.domain"]),
                          **{k: np.asarray(data[f"{prefix}qp.{k}"], float) for k in _QP})
        field = f"{prefix}meta"
        return ContactClfQp(phase_law, stance, limits, ContactClfConfig(**meta["config"]))
    except (KeyError, TypeError, ValueError) as e:
        raise ArtifactError(f"{src}: field '{field}': {e}") from None


def _check_kind(src: str, meta: dict[str, Any], kind: str, version: int) -> None:
    if meta.get("kind") != kind or meta.get("schema_version") != version:
        raise ArtifactError(f"{src}: field 'kind': not a {kind} file of version {version} "
                            f"({meta.get('kind')!r}, {meta.get('schema_version')!r})")


def load_contact_controller(path: str | os.PathLike[str], model_hash: str | None = None
                            ) -> tuple[ContactController, HumanProsthesisModel]:
    """The controller of the file and the model it was made for (ArtifactError naming the
    file and field when it is not such a file, or, with ``model_hash``, made for another
    model)."""
    src = str(path)
    meta, data = _read(path)
    _check_kind(src, meta, KIND, SCHEMA_VERSION)
    model = _model(src, meta, model_hash)
    return _controller(src, meta, data, model), model


def load_speed_following(path: str | os.PathLike[str], model_hash: str | None = None
                         ) -> tuple[FollowingSetup, HumanProsthesisModel, str]:
    """The speed-following setup of the file, the model it was made for and its gait
    library's hash (ArtifactError as :func:`load_contact_controller`)."""
    src = str(path)
    meta, data = _read(path)
    _check_kind(src, meta, FOLLOWING_KIND, FOLLOWING_SCHEMA_VERSION)
    model = _model(src, meta, model_hash)
    try:
        metas = list(meta["controllers"])
        # ContactClfQp hands over to its own kind: a Handover as SpeedFollowing uses it
        ctls: tuple[Any, ...] = tuple(_controller(src, m, data, model, f"c{i}.")
                                      for i, m in enumerate(metas))
        setup = FollowingSetup(ctls, tuple(float(v) for v in meta["speeds"]),
                               float(meta["resolution"]),
                               tuple(float(v) for v in meta["rate_speeds"]),
                               tuple(float(v) for v in meta["rates"]))
        library_hash = str(meta["library_hash"])
    except (KeyError, TypeError, ValueError) as e:
        raise ArtifactError(f"{src}: field 'meta': {e}") from None
    return setup, model, library_hash


def load_controller_file(path: str | os.PathLike[str], speed: float | None = None
                         ) -> ContactController | SpeedFollowing:
    """The controller of either kind of file: a gait's (any of :data:`LAWS`), or one following the
    person's speed over a gait library, starting at ``speed`` (m/s; None: the library's
    slowest).  ArtifactError as :func:`load_contact_controller`; ValueError for a speed with
    a single gait's file."""
    meta, _ = _read(path)
    if meta.get("kind") == FOLLOWING_KIND:
        setup = load_speed_following(path)[0]
        try:
            return setup.controller(setup.speeds[0] if speed is None else speed)
        except ValueError as e:
            raise ArtifactError(f"{path}: field 'meta': {e}") from None
    if speed is not None:
        raise ValueError(f"{path}: a single gait's controller file; a speed needs a gait "
                         "library's (speed following)")
    return load_contact_controller(path)[0]


__all__ = ["FOLLOWING_KIND", "KIND", "LAWS", "SCHEMA_VERSION", "law_of", "load_contact_controller",
           "load_controller_file", "load_speed_following", "save_contact_controller",
           "save_speed_following"]
