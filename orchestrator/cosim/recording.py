"""Working with co-simulation recordings (MCAP): read back, replay against a controller,
play frames onto a CAN bus (refitting the force tube from recorded ground truth:
:mod:`orchestrator.cosim.tube_refit`; a recording cut short: :mod:`orchestrator.cosim.recovery`).

A recording carries what it needs: the gait and tube as attachments, the run config,
versions and hashes as metadata (docs/cosim.md).
"""

from __future__ import annotations

import json
import math
import tempfile
import time
from collections.abc import Iterable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import can
from mcap.reader import make_reader

from bus_schemas.recording.reader import JsonDecoderFactory, read_messages
from bus_schemas.transport import codec


class RecordingError(ValueError):
    """A recording that cannot be used (one-line message naming the file)."""


@dataclass
class Recording:
    path: Path
    metadata: dict[str, dict[str, str]]
    attachments: dict[str, bytes]
    counts: dict[str, int]
    measurements: list[dict[str, Any]] = field(default_factory=list)
    torques: list[dict[str, Any]] = field(default_factory=list)

    @property
    def config(self) -> dict[str, Any]:
        return {k: _parse(v) for k, v in self.metadata.get("config", {}).items()}


def _parse(v: str) -> Any:
    try:
        return json.loads(v)
    except (ValueError, TypeError):
        return v


def read_recording(path: str | Path, *, messages: bool = True) -> Recording:
    """Metadata, attachments, per-channel counts and (optionally) measurements and torque
    commands of a recording."""
    p = Path(path)
    try:
        with open(p, "rb") as f:
            reader = make_reader(f, decoder_factories=[JsonDecoderFactory()])
            summary = reader.get_summary()
            meta = {m.name: dict(m.metadata) for m in reader.iter_metadata()}
            att = {a.name: bytes(a.data) for a in reader.iter_attachments()}
            counts: dict[str, int] = {}
            if summary is not None and summary.statistics is not None:
                for cid, n in summary.statistics.channel_message_counts.items():
                    counts[summary.channels[cid].topic] = n
    except FileNotFoundError:
        raise
    except Exception as e:
        raise RecordingError(f"{p}: not a readable MCAP recording ({e})") from e
    rec = Recording(p, meta, att, counts)
    if messages:
        for topic, _, obj in read_messages(p, ["/prosthesis/measurements",
                                               "/prosthesis/torque_command"]):
            (rec.measurements if topic == "/prosthesis/measurements"
             else rec.torques).append(obj)
    return rec


def _artifacts(rec: Recording, tmp: Path) -> tuple[Path, Path]:
    for name in ("gait.json", "tube.json"):
        if name not in rec.attachments:
            raise RecordingError(f"{rec.path}: attachment {name} missing")
        (tmp / name).write_bytes(rec.attachments[name])
    return tmp / "gait.json", tmp / "tube.json"


#: the attachment of a multi-contact gait's run: its controller's file
#: (:mod:`prosthesis_controller.gait_tables`), what the controller process loaded
CONTROLLER_FILE = "controller.npz"
#: a gait library's run: the library (attachment) and the speed commanded, the metadata's
#: ``profile`` (:class:`hp_model.speed_profile.SpeedProfile`'s text) and ``start`` (m/s, the
#: controller's first speed)
LIBRARY_FILE = "library.json"
SPEED_METADATA = "speed"


def _recorded_controller(rec: Recording, name: str) -> Any:
    """The controller of the recording's controller file (RecordingError naming the file
    when it cannot be built: another controller name, a damaged file)."""
    from prosthesis_controller.node import build_controller

    start = rec.metadata.get(SPEED_METADATA, {}).get("start")
    with tempfile.TemporaryDirectory() as td:
        f = Path(td) / CONTROLLER_FILE
        f.write_bytes(rec.attachments[CONTROLLER_FILE])
        try:
            return build_controller(name, None, None, tables=str(f),
                                    speed=None if start is None else float(start))
        except ValueError as e:
            raise RecordingError(f"{rec.path}: attachment {CONTROLLER_FILE}: "
                                 f"{str(e).replace(str(f), CONTROLLER_FILE)}") from None


@dataclass
class ReplayResult:
    controller: str
    cycles: int
    max_torque_diff: float  # N m, motor side, over cycles with a recorded reply
    max_diff_cycle_us: int | None


def _pitch(v: Any) -> float:
    """A recorded socket pitch: null (or absent: recordings before the IMU) is NaN."""
    return math.nan if v is None else float(v)


def recorded_profile(rec: Recording) -> Any:
    """The speed commanded in a recorded run of a person walking a gait library (its
    ``speed`` metadata's :class:`~hp_model.speed_profile.SpeedProfile`), None for any other
    run; RecordingError naming the file when the metadata is damaged."""
    from hp_model.speed_profile import SpeedProfile

    text = rec.metadata.get(SPEED_METADATA, {}).get("profile")
    if text is None:
        return None
    try:
        return SpeedProfile.parse(text)
    except ValueError as e:
        raise RecordingError(f"{rec.path}: metadata '{SPEED_METADATA}': {e}") from None


def recorded_measurement(m: dict[str, Any]) -> Any:
    """The :class:`~prosthesis_controller.measurement.ProsthesisMeasurement` of a recorded
    ``/prosthesis/measurements`` message (as the controller decoded it)."""
    from prosthesis_controller import ProsthesisMeasurement

    return ProsthesisMeasurement(m["sim_time_us"] * 1e-6, m["knee_angle"], m["ankle_angle"],
                                 m["knee_velocity"], m["ankle_velocity"], m["foot_load"],
                                 bool(m["contact"]), _pitch(m.get("socket_pitch")))


def recorded_controller(rec: Recording, name: str | None = None) -> Any:
    """The controller of a multi-contact run's recording, built from its controller file
    (``name``: default the recorded one; a gait library's starting at the recorded first
    speed).  RecordingError naming the file when it has none or it cannot be built."""
    name = name or rec.config.get("controller")
    if not name or CONTROLLER_FILE not in rec.attachments:
        raise RecordingError(f"{rec.path}: not a multi-contact run's recording (no "
                             f"{CONTROLLER_FILE} attachment)")
    return _recorded_controller(rec, name)


def replay(path: str | Path, controller: str | None = None, *, model: Any = None,
           tube: str | Path | None = None) -> ReplayResult:
    """Feed the recorded measurements (as the controller decoded them) to ``controller``
    (default: the recorded one) and compare its torque, quantized as on the bus, with the
    recorded torque commands cycle by cycle. With the same controller the difference is 0
    for a clean run (frames lost on the way make the node hold values the recording does not
    show)."""
    import hp_model
    from hp_model.force_tube import load_tube
    from hp_model.gait_artifact import load_gait
    from prosthesis_controller import make_controller

    rec = read_recording(path)
    name = controller or rec.config.get("controller")
    if not name:
        raise RecordingError(f"{rec.path}: no controller named in the recording; pass one")
    if CONTROLLER_FILE in rec.attachments:  # a multi-contact gait's run
        ctrl = _recorded_controller(rec, name)
    else:
        model = model or hp_model.load_model()
        with tempfile.TemporaryDirectory() as td:
            gp, tp = _artifacts(rec, Path(td))
            gait = load_gait(gp, model.parameter_hash())
            tb = load_tube(tube if tube is not None else tp, gait.hash())
        ctrl = make_controller(name, gait, tb, model)
    ctrl.reset()
    by_cycle = {int(t["cycle_time_us"]): t for t in rec.torques if t.get("enable")}
    worst, at = 0.0, None
    for m in rec.measurements:
        u = ctrl.tick(recorded_measurement(m)).torque
        r = by_cycle.get(int(m["sim_time_us"]))
        if r is None:
            continue
        d = max(abs(codec.quantize_torque(float(u[0])) - r["knee"]),
                abs(codec.quantize_torque(float(u[1])) - r["ankle"]))
        if d > worst:
            worst, at = d, int(m["sim_time_us"])
    return ReplayResult(name, len(rec.measurements), worst, at)


def recorded_frames(path: str | Path, directions: Iterable[str] = ("tx", "rx")
                    ) -> list[tuple[int, can.Message]]:
    """(log_time ns, frame) of the recorded CAN frames in log-time order."""
    read_recording(path, messages=False)  # RecordingError for a file that is not one
    topics = [f"/can/{d}" for d in directions]
    out = []
    for _, ns, o in read_messages(path, topics):
        out.append((ns, can.Message(timestamp=o["timestamp"], arbitration_id=o["id"],
                                    is_extended_id=bool(o.get("extended")), dlc=o["dlc"],
                                    data=bytes(o["data"]))))
    out.sort(key=lambda x: x[0])
    return out


def play_to_bus(path: str | Path, bus: can.BusABC, *, directions: Iterable[str] = ("tx",),
                speed: float = 1.0) -> int:
    """Send the recorded frames onto ``bus`` at their recorded timing (log-time deltas,
    divided by ``speed``; ``speed <= 0``: as fast as possible). Returns frames sent."""
    frames = recorded_frames(path, directions)
    if not frames:
        return 0
    t0, w0 = frames[0][0], time.perf_counter()
    for ns, msg in frames:
        if speed > 0:
            due = w0 + (ns - t0) * 1e-9 / speed
            while (left := due - time.perf_counter()) > 0:
                time.sleep(min(left, 0.001) if left > 0.002 else 0)
        bus.send(msg)
    return len(frames)


# --------------------------------------------------------------------------- refit
