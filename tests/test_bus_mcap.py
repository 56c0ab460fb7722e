"""MCAP schemas, the Recorder, the JSON decoder factory, and recordings that survive
SIGTERM/SIGINT."""

from __future__ import annotations

import io
import json
import math
import os
import signal
import subprocess
import sys
from collections import Counter
from pathlib import Path

import can
import jsonschema
import numpy as np
import pytest
from mcap.reader import make_reader
from mcap.writer import CompressionType, Writer

from bus_schemas.recording.chunk_append import append_messages, supports
from bus_schemas.recording.json_encoding import encode_json
from bus_schemas.recording.reader import JsonDecoderFactory, read_messages
from bus_schemas.recording.recorder import Recorder
from bus_schemas.recording.schemas import (
    CHANNELS,
    COORDS,
    FOXGLOVE_CHANNELS,
    MESSAGE_ENCODING,
    SCHEMA_ENCODING,
    can_frame_message,
)
from bus_schemas.transport import codec
from bus_schemas.transport.protocol import DBC_PATH, FaultFlag, QpStatus

ROOT = Path(__file__).resolve().parents[1]


def ground_truth(k: int) -> dict:
    return {"t": k * 1e-3, "socket_force": {"Fx": 10.0 + k, "Fz": -700.5, "My": 1.25},
            "q": np.linspace(0, 1, 12) + k, "qd": [0.1 * k] * 12, "domain": "ps",
            "tau": k / 10, "step": 3, "fallen": False}


def diagnostics(k: int) -> dict:
    return {"t": k * 1e-3, "controller": "clf_qp", "domain": "ps", "tau": k / 10,
            "V": 0.02, "rho": 0.0 if k else math.nan, "u": np.array([12.5, -40.0]),
            "qp_status": QpStatus.SOLVED.name.lower(), "active_constraints": ["knee_torque"],
            "fallback_count": 0, "fault_flags": int(FaultFlag.NONE), "solve_time_us": 16.0}


def measurements(k: int) -> dict:
    return {"knee_angle": codec.quantize_angle(0.1 * k), "knee_velocity": 0.5,
            "ankle_angle": -0.2, "ankle_velocity": 0.0, "foot_load": 650.0, "contact": True,
            "sim_time_us": 1000 * k, "counter": k % 16}


def test_hp_model_coordinates_match():
    import hp_model

    assert hp_model.COORDS == COORDS


def test_schemas_are_valid_and_examples_conform():
    frame = codec.encode_torque(1.0, -1.0, 2)
    examples = {
        "/can/tx": can_frame_message(frame, "tx", name="TorqueCmd"),
        "/can/rx": can_frame_message(frame, "rx", status=codec.FrameStatus.OK),
        "/prosthesis/measurements": measurements(3),
        "/prosthesis/torque_command": {"knee": 1.0, "ankle": -1.0, "knee_joint": 50.0,
                                       "ankle_joint": -50.0, "enable": True, "counter": 2},
        "/ground_truth": ground_truth(2),
        "/controller/diagnostics": diagnostics(0) | {"coverage_flag": True,
                                                     "coverage_count": 3},
        "/controller/disturbance": {"t": 0.5, "d": [0.01, -0.2], "tau": 0.4, "valid": True,
                                    "flag": False, "since_touchdown": 0.255},
        "/controller/clf": {"t": 0.5, "V": 0.0123, "rho": None},
        "/cosim/timing": {"t": 0.05, "tick": 50, "lag": 0.061, "skipped": 20},
        "/can/rates": {"t": 0.1, "window": 0.1, "tx": {"KneeFeedback": 1000.0},
                       "rx": {"TorqueCmd": 990.0, "0x7FF": 0.0}},
        "/walker/reference": {"t": 0.5, "domain": "ps", "tau": 0.4, "knee": 0.1,
                              "ankle": None, "socket_lower": {"Fx": -9.0, "Fz": -800.0,
                                                              "My": 1.0},
                              "socket_upper": {"Fx": 9.0, "Fz": -600.0, "My": 5.0}},
    }
    assert examples.keys() == CHANNELS.keys()
    for topic, schema in CHANNELS.items():
        jsonschema.Draft202012Validator.check_schema(schema)
        jsonschema.validate(json.loads(encode_json(examples[topic])), schema)
    bad = ground_truth(0) | {"q": [0.0] * 11}
    with pytest.raises(jsonschema.ValidationError):
        jsonschema.validate(json.loads(encode_json(bad)), CHANNELS["/ground_truth"])
    with pytest.raises(jsonschema.ValidationError):  # V and rho are required (null: absent)
        jsonschema.validate({"t": 0.5, "V": 0.01}, CHANNELS["/controller/clf"])
    with pytest.raises(ValueError, match="direction"):
        can_frame_message(frame, "up")


def test_can_rates_per_window_and_frame_name(tmp_path):
    """A recorder made with ``can_rates`` writes /can/rates at the end of every window of
    log time: frames per second by direction and name, names seen before listed at 0."""
    path = tmp_path / "rates.mcap"
    knee, torque = codec.encode_feedback(0.1, 0.0, 0.0, 0.0, 0.0, False, 0)[0], \
        codec.encode_torque(0.5, -0.5, 0)
    with Recorder(path, can_rates=0.01) as rec:
        for k in range(25):  # 1 kHz for 25 ms; torque replies only in the first 12 ms
            rec.write_can(knee, "tx", k * 1_000_000, name="KneeFeedback")
            if k < 12:
                rec.defer_can(torque, "rx", k * 1_000_000 + 500_000, name="TorqueCmd")
            rec.write_deferred()
        rec.write_can(can.Message(arbitration_id=0x7FF, data=b"x"), "rx", 25_000_000)
    rows = [(ns, o) for _, ns, o in read_messages(path, ["/can/rates"])]
    assert [ns for ns, _ in rows] == [10_000_000, 20_000_000]
    assert rows[0][1] == {"t": 0.01, "window": 0.01, "tx": {"KneeFeedback": 1000.0},
                          "rx": {"TorqueCmd": 1000.0}}
    assert rows[1][1]["tx"] == {"KneeFeedback": 1000.0}
    assert rows[1][1]["rx"] == {"TorqueCmd": 200.0}  # 10.5 and 11.5 ms
    with pytest.raises(ValueError, match="must be > 0"):
        Recorder(tmp_path / "x.mcap", can_rates=0.0)
    assert not list(tmp_path.glob(".x.mcap*"))  # refused before any file is made


def test_encode_json_handles_numpy_and_non_finite():
    assert encode_json({"a": np.float64(1.5), "b": np.arange(3), "c": np.int32(4)}) == \
        b'{"a":1.5,"b":[0,1,2],"c":4}'
    assert json.loads(encode_json({"x": [1.0, math.nan, -math.inf], "y": {"z": math.inf}})) \
        == {"x": [1.0, None, None], "y": {"z": None}}


def test_recorder_round_trip_every_channel(tmp_path):
    path = tmp_path / "run.mcap"
    frames = codec.encode_feedback(0.25, -1.0, 0.1, 0.0, 700.0, True, 5, sim_time_us=5000)
    with Recorder(path, metadata={"run_id": "r1", "dt": 0.001}) as rec:
        rec.register_all()
        assert rec.part_path.exists() and not path.exists()
        for k in range(100):
            t = k * 1_000_000
            for m in frames:
                rec.write_can(m, "tx", t, name=codec.decode(m).name)
            rec.write_can(codec.encode_torque(0.5, -0.5, k), "rx", t + 500_000, status="ok")
            rec.write("/prosthesis/measurements", measurements(k), t)
            rec.write("/prosthesis/torque_command", {"knee": 0.5, "ankle": -0.5,
                                                     "enable": True, "counter": k % 16}, t)
            rec.write("/ground_truth", ground_truth(k), t)
            rec.write("/controller/diagnostics", diagnostics(k), t)
        rec.add_attachment("ampro3.dbc", DBC_PATH.read_bytes(), "text/plain", 0)
        rec.add_metadata("result", {"steps": 3, "fallen": False})
        assert rec.compression is CompressionType.ZSTD
    assert path.exists() and not rec.part_path.exists() and rec.message_count == 900

    with open(path, "rb") as f:
        reader = make_reader(f, decoder_factories=[JsonDecoderFactory()])
        summary = reader.get_summary()
        assert summary is not None
        assert summary.statistics.message_count == 900
        assert {c.topic for c in summary.channels.values()} == set(CHANNELS) | set(
            FOXGLOVE_CHANNELS)
        enc = {c.topic: (c.message_encoding, summary.schemas[c.schema_id].encoding)
               for c in summary.channels.values()}
        assert all(enc[t] == (MESSAGE_ENCODING, SCHEMA_ENCODING) for t in CHANNELS)
        assert all(enc[t] == ("protobuf", "protobuf") for t in FOXGLOVE_CHANNELS)
        assert all(ci.compression == "zstd" for ci in summary.chunk_indexes)
        meta = {m.name: m.metadata for m in reader.iter_metadata()}
        assert meta["run"] == {"run_id": "r1", "dt": "0.001"}
        assert json.loads(meta["result"]["steps"]) == 3
        (att,) = list(reader.iter_attachments())
        assert att.name == "ampro3.dbc" and att.data == DBC_PATH.read_bytes()
        decoded = list(reader.iter_decoded_messages())
    counts = Counter(ch.topic for _, ch, _, _ in decoded)
    assert counts == {"/can/tx": 400, "/can/rx": 100, "/prosthesis/measurements": 100,
                      "/prosthesis/torque_command": 100, "/ground_truth": 100,
                      "/controller/diagnostics": 100}

    by_topic: dict[str, list] = {}
    for _, ch, msg, obj in decoded:
        by_topic.setdefault(ch.topic, []).append((msg.log_time, msg.sequence, obj))
    tx = by_topic["/can/tx"]
    assert [o["data"] for _, _, o in tx[:4]] == [list(m.data) for m in frames]
    assert [o["name"] for _, _, o in tx[:4]] == ["KneeFeedback", "AnkleFeedback", "FootLoad",
                                                 "SimTime"]
    assert [s for _, s, _ in tx[:5]] == [1, 2, 3, 4, 5]
    rx = by_topic["/can/rx"]
    assert rx[7][0] == 7_500_000 and rx[7][2]["status"] == "ok"
    assert codec.decode(can.Message(arbitration_id=rx[7][2]["id"], is_extended_id=False,
                                    data=bytes(rx[7][2]["data"]))).value == \
        codec.TorqueCmd(0.5, -0.5, 1)
    gt = by_topic["/ground_truth"][42]
    assert gt[0] == 42_000_000
    assert gt[2]["q"] == (np.linspace(0, 1, 12) + 42).tolist()
    assert gt[2]["socket_force"] == {"Fx": 52.0, "Fz": -700.5, "My": 1.25}
    diag = [o for _, _, o in by_topic["/controller/diagnostics"]]
    assert diag[0]["rho"] is None and diag[1]["rho"] == 0.0 and diag[5]["u"] == [12.5, -40.0]
    meas = by_topic["/prosthesis/measurements"][9][2]
    assert meas["knee_angle"] == codec.quantize_angle(0.9)
    # the convenience reader agrees
    assert sum(1 for _ in read_messages(path, ["/ground_truth"])) == 100


@pytest.mark.parametrize("compression", [CompressionType.NONE, CompressionType.ZSTD])
def test_append_messages_writes_the_bytes_add_message_writes(compression):
    """The one-pack path leaves the same file as mcap's add_message: several chunks, three
    channels, log times out of order, empty and large payloads."""
    rng = np.random.default_rng(7)
    rows = []
    for k in range(600):
        cid = int(rng.integers(1, 4))
        size = int(rng.choice([0, 3, 40, 700]))
        rows.append((cid, k + 1, int(rng.integers(0, 10**12)), int(rng.integers(0, 10**12)),
                     bytes(rng.integers(0, 256, size, dtype=np.uint8))))
    files = []
    for fast in (False, True):
        buf = io.BytesIO()
        w = Writer(buf, chunk_size=4096, compression=compression)
        w.start(profile="", library="test")
        sid = w.register_schema("s", "jsonschema", b"{}")
        for topic in ("/a", "/b", "/c"):
            w.register_channel(topic, "json", sid)
        if fast:
            assert supports(w)
            assert append_messages(w, rows[:250]) == 250  # a batch, then one by one
            for r in rows[250:]:
                append_messages(w, [r])
        else:
            for cid, seq, t, pub, data in rows:
                w.add_message(channel_id=cid, log_time=t, data=data, publish_time=pub,
                              sequence=seq)
        w.finish()
        files.append(buf.getvalue())
    assert files[0] == files[1]
    reader = make_reader(io.BytesIO(files[1]))
    assert reader.get_summary().statistics.message_count == 600
    assert len(reader.get_summary().chunk_indexes) > 10
    got = sorted((m.log_time, m.sequence, m.data) for _, _, m in reader.iter_messages())
    assert got == sorted((t, seq, data) for _, seq, t, _, data in rows)


def test_deferred_writes_are_built_late_written_in_order_and_on_finish(tmp_path):
    path = tmp_path / "d.mcap"
    built = []

    def gt(k: int) -> dict:
        built.append(k)
        return ground_truth(k)

    rec = Recorder(path)
    rec.register_all()
    frame = codec.encode_torque(0.5, -0.5, 3)
    rec.defer_can(frame, "rx", 5, name="TorqueCmd", status="ok")
    rec.defer_call("/ground_truth", 7, gt, 7)
    rec.defer("/prosthesis/measurements", measurements(2), 2)
    assert rec.deferred == 3 and built == [] and rec.message_count == 0
    assert rec.write_deferred() == 3 and built == [7] and rec.deferred == 0
    rec.defer_call("/ground_truth", 9, gt, 9)  # left for finish()
    with pytest.raises(ValueError, match="direction"):
        rec.defer_can(frame, "up")
    rec.finish()
    assert built == [7, 9] and rec.message_count == 4
    got = [(topic, ns, obj) for topic, ns, obj in read_messages(path)]
    assert [(t, ns) for t, ns, _ in got] == [("/prosthesis/measurements", 2),
                                             ("/can/rx", 5), ("/ground_truth", 7),
                                             ("/ground_truth", 9)]
    assert got[1][2] == json.loads(encode_json(can_frame_message(frame, "rx", name="TorqueCmd",
                                                                 status="ok")))
    assert got[3][2] == json.loads(encode_json(ground_truth(9)))


@pytest.mark.parametrize("compression", ["none", "zstd"])
def test_write_many_leaves_the_bytes_of_one_write_at_a_time(tmp_path, compression):
    """A batch of an event's records (what ``write_deferred`` appends at once) gives the file
    that writing them one by one gives: CAN frames closing ``/can/rates`` windows, several
    chunks, pre-encoded bytes; a bad record mid-batch leaves the records before it written
    and raises as ``write`` does."""
    frames = [codec.encode_torque(0.1 * k, -0.1 * k, k % 16) for k in range(40)]
    rows = []
    for k, f in enumerate(frames):
        ns = 250_000 * k
        rows.append(("/can/rx", can_frame_message(f, "rx", name="TorqueCmd", status="ok"), ns))
        rows.append(("/ground_truth", ground_truth(k), ns))
        rows.append(("/prosthesis/measurements", encode_json(measurements(k)), ns))
    files = []
    for batched in (False, True):
        path = tmp_path / f"{batched}.mcap"
        rec = Recorder(path, compression=compression, chunk_size=2048, can_rates=0.001)
        if batched:
            for i in range(0, len(rows), 6):
                assert rec.write_many(rows[i:i + 6]) == len(rows[i:i + 6])
        else:
            for topic, message, ns in rows:
                rec.write(topic, message, ns)
        count = rec.message_count
        rec.finish()
        files.append((path.read_bytes(), count))
    assert files[0] == files[1]
    topics = Counter(t for t, _, _ in read_messages(tmp_path / "True.mcap"))
    assert topics["/can/rates"] == 9 and topics["/can/rx"] == 40
    rec = Recorder(tmp_path / "bad.mcap", compression=compression)
    with pytest.raises(KeyError, match="no schema"):
        rec.write_many([rows[1], ("/unknown", {"a": 1}, 5), rows[4]])
    rec.finish()
    assert [t for t, _, _ in read_messages(tmp_path / "bad.mcap")] == ["/ground_truth"]


def test_writes_after_finish_are_refused(tmp_path):
    rec = Recorder(tmp_path / "a.mcap", compression="none")
    rec.write("/ground_truth", ground_truth(0), 0)
    assert rec.finish() == tmp_path / "a.mcap" and rec.finish() == tmp_path / "a.mcap"
    with pytest.raises(RuntimeError, match="finished"):
        rec.write("/ground_truth", ground_truth(1), 1)
    with pytest.raises(KeyError, match="no schema"):
        Recorder(tmp_path / "b.mcap").add_channel("/unknown")


def test_exception_inside_with_still_leaves_a_complete_file(tmp_path):
    path = tmp_path / "err.mcap"
    with pytest.raises(ZeroDivisionError), Recorder(path) as rec:
        rec.write("/ground_truth", ground_truth(0), 0)
        1 / 0  # noqa: B018
    assert [t for t, _, _ in read_messages(path)] == ["/ground_truth"]


def test_signal_in_process_finishes_without_exit(tmp_path):
    path = tmp_path / "sig.mcap"
    before = signal.getsignal(signal.SIGTERM)
    rec = Recorder(path)
    rec.install_signal_handlers([signal.SIGTERM], exit=False)
    for k in range(3):
        rec.write("/ground_truth", ground_truth(k), k)
    for k in range(3, 5):  # queued, not yet written: part of the file all the same
        rec.defer_call("/ground_truth", k, ground_truth, k)
    os.kill(os.getpid(), signal.SIGTERM)  # handled in this thread at the next bytecode
    assert rec.interrupted == signal.SIGTERM and rec.finished
    rec.write("/ground_truth", ground_truth(6), 6)  # dropped, not an error
    assert rec.dropped == 1
    assert signal.getsignal(signal.SIGTERM) == before  # handlers restored
    with open(path, "rb") as f:
        reader = make_reader(f)
        assert reader.get_summary().statistics.message_count == 5
        meta = {m.name: m.metadata for m in reader.iter_metadata()}
    assert meta["signal"] == {"signal": "SIGTERM", "messages": "5"}


def _recorder_process(path: Path, ready_after: int) -> subprocess.Popen:
    """``tests/bus_record_node.py`` recording to ``path`` in its own OS process."""
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    return subprocess.Popen([sys.executable, str(ROOT / "tests" / "bus_record_node.py"),
                             str(path), str(ready_after)], stdout=subprocess.PIPE, text=True,
                            env=env)


@pytest.mark.parametrize(("sig", "code"), [(signal.SIGTERM, 143), (signal.SIGINT, 130)])
def test_subprocess_interrupted_mid_recording_leaves_a_complete_file(tmp_path, sig, code):
    path = tmp_path / "killed.mcap"
    proc = _recorder_process(path, 200)
    try:
        assert proc.stdout is not None and proc.stdout.readline().strip() == "ready"
        proc.send_signal(sig)
        assert proc.wait(20) == code
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert path.exists() and not (tmp_path / ".killed.mcap.part").exists()
    with open(path, "rb") as f:
        reader = make_reader(f, validate_crcs=True, decoder_factories=[JsonDecoderFactory()])
        summary = reader.get_summary()
        n = summary.statistics.message_count
        meta = {m.name: m.metadata for m in reader.iter_metadata()}
        msgs = list(reader.iter_decoded_messages())
    assert n >= 200 and len(msgs) == n
    assert meta["signal"]["signal"] == signal.Signals(sig).name
    assert int(meta["signal"]["messages"]) == n
    gts = [o for _, ch, _, o in msgs if ch.topic == "/ground_truth"]
    assert [g["t"] for g in gts] == pytest.approx([k * 1e-3 for k in range(len(gts))])


def test_two_runs_never_write_the_same_recording(tmp_path):
    """A second writer of the same path (here another process) fails at once with a clear
    error while the first goes on and completes; a part file left by a killed run is not
    locked and is reused."""
    import textwrap

    from bus_schemas.recording.part_file import RecordingInUseError

    path = tmp_path / "run.mcap"
    code = textwrap.dedent(f"""
        import sys
        from bus_schemas.recording.recorder import Recorder
        rec = Recorder({str(path)!r})
        rec.register_all()
        print("open", flush=True)
        sys.stdin.readline()
        rec.finish()
        """)
    p = subprocess.Popen([sys.executable, "-c", code], cwd=ROOT, stdin=subprocess.PIPE,
                         stdout=subprocess.PIPE, text=True)
    try:
        assert p.stdout.readline().strip() == "open"
        with pytest.raises(RecordingInUseError, match="another run is writing"):
            Recorder(path)
        p.stdin.write("\n")
        p.stdin.flush()
        assert p.wait(30) == 0
    finally:
        p.kill()
    assert _summary(path) is not None  # the first run's file is complete
    # a stale part (its writer killed) is not locked: a new run takes it
    stale = path.with_name(f".{path.name}.part")
    stale.write_bytes(b"half a file")
    with Recorder(path) as rec:
        rec.register_all()
    assert not stale.exists() and _summary(path) is not None


def _summary(path):
    with open(path, "rb") as f:
        return make_reader(f).get_summary()


def test_a_killed_runs_recording_is_recovered(tmp_path, capsys):
    """SIGKILL leaves only the .part file; ``hpcosim recording recover`` restores every
    complete chunk into a complete MCAP (summary, indexes) whose ground truth runs without
    a hole from the first millisecond; it never overwrites a file."""
    from orchestrator.cli import main

    path = tmp_path / "killed.mcap"
    part = tmp_path / ".killed.mcap.part"
    proc = _recorder_process(path, 8000)
    try:
        assert proc.stdout is not None and proc.stdout.readline().strip() == "ready"
        proc.kill()
        proc.wait(20)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert part.exists() and not path.exists()
    with pytest.raises(Exception), open(part, "rb") as f:  # noqa: B017 - no summary
        make_reader(f).get_summary().statistics  # noqa: B018
    assert main(["recording", "recover", str(part)]) == 0
    assert "recovered" in capsys.readouterr().out
    with open(path, "rb") as f:
        reader = make_reader(f, validate_crcs=True, decoder_factories=[JsonDecoderFactory()])
        n = reader.get_summary().statistics.message_count
        meta = {m.name: m.metadata for m in reader.iter_metadata()}
        msgs = list(reader.iter_decoded_messages())
    assert len(msgs) == n >= 2000  # at least one 512 KiB chunk was complete
    assert meta["run"] == {"node": "bus_record_node"}  # the run's own metadata came along
    assert meta["recovered"]["complete_input"] == "false"
    gts = [o["t"] for _, ch, _, o in msgs if ch.topic == "/ground_truth"]
    assert gts == pytest.approx([k * 1e-3 for k in range(len(gts))])
    # each millisecond: the feedback frames, then the ground truth (a chunk may end between)
    per = len(codec.encode_feedback(0.0, 0.0, 0.0, 0.0, 500.0, True, 0))
    frames = len([1 for _, ch, _, _ in msgs if ch.topic != "/ground_truth"])
    assert 0 <= frames - per * len(gts) <= per
    # never overwritten: a second recovery to the same name is one line, exit 2
    assert main(["recording", "recover", str(part)]) == 2
    assert "exists" in capsys.readouterr().err
    assert main(["recording", "recover", str(part), "--out", str(tmp_path / "b.mcap")]) == 0
