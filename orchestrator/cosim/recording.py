"""Working with co-simulation recordings (MCAP): read back, replay against a controller,
play frames onto a CAN bus, refit the force tube from recorded ground truth (a recording cut
short: :mod:`orchestrator.cosim.recovery`).

A recording carries what it needs: the gait and tube as attachments, the run config,
versions and hashes as metadata (docs/cosim.md).
"""

from __future__ import annotations

import json
import math
import tempfile
import time
from collections.abc import Iterable
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import can
import numpy as np
from mcap.reader import make_reader

from bus_schemas.recording.reader import JsonDecoderFactory, read_messages
from bus_schemas.transport import codec
from hp_model.domains import Domain


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


def _recorded_controller(rec: Recording, name: str) -> Any:
    """The controller of the recording's controller file (RecordingError naming the file
    when it cannot be built: another controller name, a damaged file)."""
    from prosthesis_controller.node import build_controller

    with tempfile.TemporaryDirectory() as td:
        f = Path(td) / CONTROLLER_FILE
        f.write_bytes(rec.attachments[CONTROLLER_FILE])
        try:
            return build_controller(name, None, None, tables=str(f))
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
    from prosthesis_controller import ProsthesisMeasurement, make_controller

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
        meas = ProsthesisMeasurement(m["sim_time_us"] * 1e-6, m["knee_angle"],
                                     m["ankle_angle"], m["knee_velocity"],
                                     m["ankle_velocity"], m["foot_load"], bool(m["contact"]),
                                     _pitch(m.get("socket_pitch")))
        u = ctrl.tick(meas).torque
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


def ps_profiles(path: str | Path) -> list[tuple[np.ndarray, np.ndarray]]:
    """Recorded ground-truth socket force of every complete prosthesis-stance (ps) portion:
    (tau (n,), F_s (n, 3)). A ps portion is complete when it starts at the run start or at
    an impact into ps and ends with the impact into pns."""
    rows = [o for _, _, o in read_messages(path, ["/ground_truth"])]
    out, cur, complete_start = [], [], True
    prev = None
    for o in rows:
        d = o["domain"]  # the domain's word
        if d == Domain.PS:
            if prev == Domain.PNS:
                cur, complete_start = [], True
            f = o["socket_force"]
            cur.append((o["tau"], f["Fx"], f["Fz"], f["My"]))
        elif prev == Domain.PS and cur and complete_start:
            a = np.array(cur, dtype=float)
            out.append((a[:, 0], a[:, 1:]))
            cur = []
        prev = d
    return out


def refit_tube(paths: Iterable[str | Path], gait_path: str | Path, out: str | Path, *,
               old_tube: str | Path | None = None, degree: int = 3,
               model: Any = None) -> dict[str, Any]:
    """Refit the force tube from the recorded ps portions of ``paths``; report coverage of
    the old tube (``old_tube``, default the tube attached to the first recording): the
    fraction of samples and of steps inside it."""
    import hp_model
    from characterization.tube.fit import fit_tube, nominal_coefficients
    from hp_model.force_tube import save_tube
    from hp_model.gait_artifact import load_gait

    model = model or hp_model.load_model()
    gait = load_gait(gait_path, model.parameter_hash())
    paths = [Path(p) for p in paths]
    _check_gait(paths, gait, gait_path, model)
    steps: list[tuple[np.ndarray, np.ndarray]] = []
    for p in paths:
        steps.extend(ps_profiles(p))
    if len(steps) < degree + 2:
        raise RecordingError(f"{len(steps)} complete ps steps in {len(paths)} recordings; "
                             f"need at least {degree + 2}")
    tau_lo = max(0.0, max(float(s[0].min()) for s in steps))
    tau_hi = min(1.0, min(float(s[0].max()) for s in steps))
    nominal = nominal_coefficients(gait, tau_lo, tau_hi)
    profiles = []
    for tau, fs in steps:
        keep = (tau >= tau_lo) & (tau <= tau_hi)
        profiles.append((tau[keep], fs[keep] - gait.socket_force(tau[keep])))
    tube = fit_tube(profiles, nominal, tau_lo, tau_hi, degree=degree, gait_hash=gait.hash(),
                    source={"recordings": [str(p) for p in paths]})
    old = _old_tube(paths[0], old_tube, gait.hash())
    if old is not None and old.model_error is not None:  # the socket force only is refitted
        tube = replace(tube, model_error=old.model_error)
    save_tube(out, tube)
    report: dict[str, Any] = {"steps": len(steps), "tau_lo": tau_lo, "tau_hi": tau_hi,
                              "out": str(out)}
    if old is not None:
        inside_s, n_s, inside_steps = 0, 0, 0
        for tau, fs in steps:
            ok = old.contains(tau, fs - old.nominal_force(tau))
            inside_s += int(ok.sum())
            n_s += ok.size
            inside_steps += bool(ok.all())
        report["old_coverage_samples"] = inside_s / max(1, n_s)
        report["old_coverage_steps"] = inside_steps / len(steps)
    return report


def _check_gait(paths: Iterable[str | Path], gait: Any, gait_path: str | Path, model: Any) -> None:
    """Every recording was made with ``gait`` (its attached gait has the same hash): a tube
    refitted against another gait's phase and nominal force would be mislabelled."""
    from hp_model.artifacts import ArtifactError
    from hp_model.gait_artifact import load_gait

    for p in paths:
        rec = read_recording(p, messages=False)
        if "gait.json" not in rec.attachments:
            raise RecordingError(f"{p}: attachment gait.json missing")
        with tempfile.TemporaryDirectory() as td:
            f = Path(td) / "gait.json"
            f.write_bytes(rec.attachments["gait.json"])
            try:
                h = load_gait(f, model.parameter_hash()).hash()
            except ArtifactError as e:
                raise RecordingError(f"{p}: its gait does not fit this model "
                                     f"({str(e).replace(str(f), 'gait.json')})") from None
        if h != gait.hash():
            raise RecordingError(f"{p}: recorded with gait {h}, not with {gait_path} "
                                 f"({gait.hash()})")


def _old_tube(first: str | Path, old_tube: str | Path | None, gait_hash: str) -> Any:
    """The tube to compare with: ``old_tube``, else the one attached to the recording
    ``first`` (None when it has none)."""
    from hp_model.force_tube import load_tube

    if old_tube is not None:
        return load_tube(old_tube, gait_hash)
    rec = read_recording(first, messages=False)
    if "tube.json" not in rec.attachments:
        return None
    with tempfile.TemporaryDirectory() as td:
        (Path(td) / "tube.json").write_bytes(rec.attachments["tube.json"])
        return load_tube(Path(td) / "tube.json", gait_hash)


# ----------------------------------------------------------- model-error refit

#: a gap between two recorded estimates longer than this starts a new stance (s)
STANCE_GAP = 0.005


def disturbance_samples(path: str | Path) -> list[Any]:
    """The controller's recorded model-error estimates (``/controller/disturbance``, valid
    ones only) of a recording, one :class:`characterization.tube.model_error.ErrorSamples`
    per stance (a new stance where the time since touchdown drops or the ticks are more
    than :data:`STANCE_GAP` apart)."""
    from characterization.tube.model_error import ErrorSamples

    rows = [o for _, _, o in read_messages(path, ["/controller/disturbance"])
            if o.get("valid")]
    rows.sort(key=lambda o: o["t"])
    out: list[Any] = []
    cur: list[tuple[float, float, float, float]] = []
    prev: dict[str, Any] | None = None
    for o in rows:
        if prev is not None and (o["t"] - prev["t"] > STANCE_GAP
                                 or o["since_touchdown"] < prev["since_touchdown"]):
            out.append(cur)
            cur = []
        cur.append((o["tau"], o["since_touchdown"], o["d"][0], o["d"][1]))
        prev = o
    if cur:
        out.append(cur)
    res = []
    for c in out:
        a = np.array(c, float)
        res.append(ErrorSamples(a[:, 0], a[:, 1], a[:, 2:4]))
    return res


def refit_model_error(paths: Iterable[str | Path], gait_path: str | Path, out: str | Path, *,
                      old_tube: str | Path | None = None, degree: int = 3,
                      exclude_after_touchdown: float | None = None, model: Any = None
                      ) -> dict[str, Any]:
    """Refit the tube's model-error bound (schema 2, ``model_error``) from the controller's
    recorded online estimates (``CtrlDisturbance``) of ``paths``; the socket-force tube is
    kept from ``old_tube`` (default: the tube attached to the first recording).  Reports the
    coverage of the old bound (fraction of the recorded estimates where it is defined that
    lie inside it; None without one).  ``exclude_after_touchdown`` defaults to the old
    bound's, else 30 ms.  Writes ``out`` atomically."""
    import hp_model
    from characterization.tube.fit import TubeFitError
    from characterization.tube.model_error import fit_model_error
    from hp_model.force_tube import EXCLUDE_AFTER_TOUCHDOWN, save_tube
    from hp_model.gait_artifact import load_gait

    model = model or hp_model.load_model()
    gait = load_gait(gait_path, model.parameter_hash())
    paths = [Path(p) for p in paths]
    _check_gait(paths, gait, gait_path, model)
    old = _old_tube(paths[0], old_tube, gait.hash())
    if old is None:
        raise RecordingError(f"{paths[0]}: no tube attached; pass the tube to refit with "
                             "--old")
    samples = []
    for p in paths:
        samples.extend(disturbance_samples(p))
    if not samples:
        raise RecordingError(f"no model-error estimates in {len(paths)} recording(s) (a "
                             "controller without an estimator, e.g. not clfqp?)")
    ex = (exclude_after_touchdown if exclude_after_touchdown is not None
          else old.model_error.exclude_after_touchdown if old.model_error is not None
          else EXCLUDE_AFTER_TOUCHDOWN)
    report: dict[str, Any] = {"stances": len(samples), "out": str(out)}
    if old.model_error is not None:
        me = old.model_error
        inside = n = 0
        for e in samples:
            m = me.in_range(e.tau, e.since_touchdown)
            inside += int(me.contains(e.tau[m], e.d[m]).sum())
            n += int(m.sum())
        report["old_coverage_samples"] = inside / n if n else None
    else:
        report["old_coverage_samples"] = None
    try:
        bound = fit_model_error(samples, degree, ex, source={
            "recordings": [str(p) for p in paths],
            "method_d": "the controller's online estimate (CtrlDisturbance): filtered finite "
                        "difference of the measured joint velocities vs a + A u_prev"})
    except TubeFitError as e:
        raise RecordingError(f"model-error refit: {e}") from None
    save_tube(out, replace(old, model_error=bound))
    report.update({"tau_lo": bound.tau_lo, "tau_hi": bound.tau_hi,
                   "n_samples": bound.source["n_samples"],
                   "samples_inside": bound.credibility["samples_inside_fraction"]})
    return report
