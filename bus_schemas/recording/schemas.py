"""The MCAP channels of a run: their JSON schemas (Foxglove-readable) and topics.

Channels (schema encoding ``jsonschema``, message encoding ``json``), see :data:`CHANNELS`:

- ``/can/tx``, ``/can/rx``: ``hpcosim.CanFrame``, frames plant -> controller and back
  (:func:`can_frame_message`);
- ``/prosthesis/measurements``: ``hpcosim.ProsthesisMeasurements``, decoded feedback;
- ``/prosthesis/torque_command``: ``hpcosim.TorqueCommand``, decoded torque commands;
- ``/ground_truth``: ``hpcosim.GroundTruth``, plant state and socket force;
- ``/controller/diagnostics``: ``hpcosim.ControllerDiagnostics``, tau, V, rho, QP status;
- ``/controller/clf``: ``hpcosim.ControllerClf``, the controller's CLF value V and
  relaxation rho of every period (``CtrlClf`` frames; null when absent);
- ``/controller/disturbance``: ``hpcosim.ControllerDisturbance``, the model-error estimate;
- ``/cosim/timing``: ``hpcosim.PlantTiming``, a realtime plant's overruns;
- ``/can/rates``: ``hpcosim.CanRates``, frames per second of each frame name and direction
  over windows of 100 ms log time (a recorder made with ``can_rates``);
- ``/walker/reference``: ``hpcosim.WalkerReference``, the gait's desired prosthesis angles
  and the force tube at the recorded phase (every 10 ms).

Foxglove channels (schema and message encoding ``protobuf``, the messages and schemas of the
``foxglove-schemas-protobuf`` package, :mod:`bus_schemas.recording.foxglove`), see
:data:`FOXGLOVE_CHANNELS`:

- ``/walker/tf``: ``foxglove.FrameTransforms``, the walker's frames (every 10 ms);
- ``/walker/scene``: ``foxglove.SceneUpdate``, the walker drawn with primitives.

Units: SI (s, rad, rad/s, N, N m); ``log_time`` of every message in ns (simulation time in
lockstep runs, wall time otherwise). Domains are the words of
:class:`hp_model.domains.Domain`; coordinates those of ``hp_model.COORDS``.
"""

from __future__ import annotations

from collections.abc import Iterable
from typing import Any

import can

from hp_model import COORDS
from hp_model.domains import PAPER_DOMAINS

SCHEMA_ENCODING = "jsonschema"
MESSAGE_ENCODING = "json"
PROTOBUF_ENCODING = "protobuf"  # schema and message encoding of the Foxglove channels


def _num(desc: str) -> dict[str, Any]:
    return {"type": ["number", "null"], "description": desc}


def _int(desc: str) -> dict[str, Any]:
    return {"type": "integer", "description": desc}


def _domain(desc: str, *extra: None) -> dict[str, Any]:
    """A domain: one of the words of :class:`Domain` (definition order), or ``extra``."""
    return {"enum": [*(d.value for d in PAPER_DOMAINS), *extra], "description": desc}


def _vec(n: int, desc: str) -> dict[str, Any]:
    return {"type": "array", "items": {"type": ["number", "null"]}, "minItems": n,
            "maxItems": n, "description": desc}


def _schema(title: str, desc: str, props: dict[str, Any], required: Iterable[str]
            ) -> dict[str, Any]:
    return {"$schema": "https://json-schema.org/draft/2020-12/schema", "title": title,
            "description": desc, "type": "object", "properties": props,
            "required": list(required)}


CAN_FRAME = _schema("hpcosim.CanFrame", "One CAN frame as seen by the plant side.", {
    "timestamp": _num("frame timestamp as sent [s]"),
    "id": _int("arbitration id"),
    "extended": {"type": "boolean", "description": "29-bit id"},
    "dlc": _int("data length code"),
    "data": {"type": "array", "items": {"type": "integer", "minimum": 0, "maximum": 255},
             "maxItems": 64, "description": "data bytes"},
    "direction": {"enum": ["tx", "rx"], "description": "tx: plant->ctrl, rx: ctrl->plant"},
    "name": {"type": ["string", "null"], "description": "frame name in ampro3.dbc"},
    "status": {"type": ["string", "null"],
               "description": "receiver's classification (ok, bad_checksum, ...)"},
}, ["timestamp", "id", "dlc", "data", "direction"])

PROSTHESIS_MEASUREMENTS = _schema(
    "hpcosim.ProsthesisMeasurements", "What the controller senses, as decoded from CAN.", {
        "knee_angle": _num("th_pk [rad]"), "knee_velocity": _num("d th_pk / dt [rad/s]"),
        "ankle_angle": _num("th_pa [rad]"), "ankle_velocity": _num("d th_pa / dt [rad/s]"),
        "foot_load": _num("foot normal load [N]"),
        "contact": {"type": "boolean", "description": "foot in contact"},
        "socket_pitch": _num("world pitch of the prosthesis top link from the IMU [rad]; "
                             "null: no valid IMU reading"),
        "sim_time_us": _int("plant sim time [us], mod 2^32"),
        "counter": _int("rolling counter of the frames"),
    }, ["knee_angle", "knee_velocity", "ankle_angle", "ankle_velocity", "foot_load",
        "contact"])

TORQUE_COMMAND = _schema("hpcosim.TorqueCommand", "Torque command as decoded from CAN.", {
    "knee": _num("knee motor torque [N m]"), "ankle": _num("ankle motor torque [N m]"),
    "knee_joint": _num("knee joint torque = gear ratio x motor torque [N m]"),
    "ankle_joint": _num("ankle joint torque [N m]"),
    "enable": {"type": "boolean", "description": "torque enable"},
    "counter": _int("rolling counter"),
}, ["knee", "ankle", "enable"])

GROUND_TRUTH = _schema("hpcosim.GroundTruth", "Plant state; recorded, never sent to the "
                       "controller.", {
    "t": _num("simulation time [s]"),
    "socket_force": {"type": "object", "description": "socket force F_s on the prosthesis",
                     "properties": {"Fx": _num("[N]"), "Fz": _num("[N]"),
                                    "My": _num("[N m]")},
                     "required": ["Fx", "Fz", "My"]},
    "q": _vec(12, "generalized coordinates " + ", ".join(COORDS) + " [m, rad]"),
    "qd": _vec(12, "generalized velocities [m/s, rad/s]"),
    "domain": _domain("prosthesis stance / non-stance"),
    "tau": _num("phase variable tau(q) [1]"),
    "step": _int("step count"),
    "fallen": {"type": "boolean", "description": "fall detected"},
}, ["t", "socket_force", "q", "qd", "domain", "tau", "step", "fallen"])

CONTROLLER_DIAGNOSTICS = _schema(
    "hpcosim.ControllerDiagnostics", "Prosthesis controller internals per control period.", {
        "t": _num("controller time [s]"),
        "controller": {"type": "string", "description": "clf_qp, relaxed, pd, ..."},
        "domain": _domain("domain the controller uses", None),
        "tau": _num("phase variable [1]"),
        "V": _num("CLF value V_eps"),
        "rho": _num("CLF relaxation rho"),
        "u": _vec(2, "joint torques u_p (knee, ankle) [N m]"),
        "qp_status": {"type": "string", "description": "QpStatus name"},
        "active_constraints": {"type": "array", "items": {"type": "string"},
                               "description": "names of active QP constraints"},
        "fallback_count": _int("control periods on the fallback controller"),
        "fault_flags": _int("FaultFlag bits"),
        "solve_time_us": _num("QP solve time [us]"),
        "coverage_flag": {"type": "boolean", "description": "the model-error estimate was "
                          "outside the characterised bound on the last tick"},
        "coverage_count": _int("ticks flagged by the coverage monitor (saturating, 127)"),
    }, ["t", "tau", "V", "rho", "u", "qp_status", "active_constraints", "fallback_count",
        "fault_flags"])

CONTROLLER_DISTURBANCE = _schema(
    "hpcosim.ControllerDisturbance", "The controller's online model-error estimate "
    "(CtrlDisturbance frame): d = nu - (a + A u) of the interaction-aware CLF-QP.", {
        "t": _num("controller time of the tick [s] (the frame's timestamp)"),
        "d": _vec(2, "estimated model error (dy1 [m/s^2], d2y2 [rad/s^2]), as on the bus"),
        "tau": _num("stance phase of the tick [1]"),
        "valid": {"type": "boolean", "description": "the estimate has settled"},
        "flag": {"type": "boolean",
                 "description": "outside the characterised bound (coverage monitor)"},
        "since_touchdown": _num("time since the switch to stance [s], saturating at 0.255"),
    }, ["t", "d", "tau", "valid", "flag", "since_touchdown"])

CONTROLLER_CLF = _schema(
    "hpcosim.ControllerClf", "The controller's CLF value and relaxation of one control "
    "period as the loop received them (CtrlClf frame in a co-simulation: V step 1e-5, rho "
    "step 1e-3).", {
        "t": _num("simulation time of the period [s]"),
        "V": _num("CLF value V_eps [1], >= 0 (0 in pns); null: not received or absent"),
        "rho": _num("CLF-QP relaxation rho [1], >= 0; null: absent (a controller without a "
                    "relaxation) or not received"),
    }, ["t", "V", "rho"])

PLANT_TIMING = _schema(
    "hpcosim.PlantTiming", "A realtime plant tick begun a period or more behind its "
    "wall-clock slot (an overrun), and the slots skipped to catch up.", {
        "t": _num("simulation time of the tick [s]"),
        "tick": _int("tick index"),
        "lag": _num("wall-clock lag behind the tick's slot at its start [s]"),
        "skipped": _int("wall-clock slots skipped at this tick (lag past max_lag), 0 if none"),
    }, ["t", "tick", "lag", "skipped"])

_RATES = {"type": "object", "additionalProperties": {"type": "number"}}

CAN_RATES = _schema(
    "hpcosim.CanRates", "CAN frames per second over one window of log time, by frame name "
    "(ampro3.dbc; 0x... for an id it does not name); every name seen so far is listed.", {
        "t": _num("end of the window [s] (log time)"),
        "window": _num("window length [s]"),
        "tx": {**_RATES, "description": "plant -> controller [1/s]"},
        "rx": {**_RATES, "description": "controller -> plant [1/s]"},
    }, ["t", "window", "tx", "rx"])

_FORCE = {"type": ["object", "null"], "properties": {"Fx": _num("[N]"), "Fz": _num("[N]"),
                                                    "My": _num("[N m]")}}

WALKER_REFERENCE = _schema(
    "hpcosim.WalkerReference", "The gait's desired prosthesis joint angles and the force "
    "tube at the plant's phase tau(q) (recorded every 10 ms with /walker/tf).", {
        "t": _num("simulation time [s]"),
        "domain": _domain("prosthesis stance / non-stance"),
        "tau": _num("phase variable tau(q) [1]"),
        "knee": _num("desired th_pk (the gait's Bezier output at tau clipped to [0, 1]) "
                     "[rad]"),
        "ankle": _num("desired th_pa [rad]; null in ps (the stance ankle is not an output)"),
        "socket_lower": {**_FORCE, "description": "force tube's lower bound on the socket "
                         "force F_s at tau (ps only, else null)"},
        "socket_upper": {**_FORCE, "description": "force tube's upper bound (ps only)"},
    }, ["t", "domain", "tau", "knee", "ankle", "socket_lower", "socket_upper"])

#: topic -> JSON schema
CHANNELS: dict[str, dict[str, Any]] = {
    "/can/tx": CAN_FRAME,
    "/can/rx": CAN_FRAME,
    "/prosthesis/measurements": PROSTHESIS_MEASUREMENTS,
    "/prosthesis/torque_command": TORQUE_COMMAND,
    "/ground_truth": GROUND_TRUTH,
    "/controller/diagnostics": CONTROLLER_DIAGNOSTICS,
    "/controller/disturbance": CONTROLLER_DISTURBANCE,
    "/controller/clf": CONTROLLER_CLF,
    "/cosim/timing": PLANT_TIMING,
    "/can/rates": CAN_RATES,
    "/walker/reference": WALKER_REFERENCE,
}

#: topic -> Foxglove protobuf message (``foxglove-schemas-protobuf``)
FOXGLOVE_CHANNELS: dict[str, str] = {
    "/walker/tf": "foxglove.FrameTransforms",
    "/walker/scene": "foxglove.SceneUpdate",
}


def can_frame_message(msg: can.Message, direction: str, *, name: str | None = None,
                      status: str | None = None) -> dict[str, Any]:
    """The ``hpcosim.CanFrame`` record of a python-can message."""
    if direction not in ("tx", "rx"):
        raise ValueError(f"direction {direction!r}: expected 'tx' or 'rx'")
    return {"timestamp": float(msg.timestamp), "id": int(msg.arbitration_id),
            "extended": bool(msg.is_extended_id), "dlc": int(msg.dlc),
            "data": list(msg.data or b""), "direction": direction, "name": name,
            "status": None if status is None else str(status)}

