"""The AMPRO3-style DBC, CRC, codec (fast path bit-identical to cantools), quantization
and the frame checker."""

from __future__ import annotations

import itertools
import math
import struct

import can
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from bus_schemas.transport import codec, protocol
from bus_schemas.transport.codec import FrameChecker, FrameStatus
from bus_schemas.transport.crc8 import crc8, frame_checksum
from bus_schemas.transport.protocol import CtrlState, FaultFlag, FrameId, QpStatus

PROTECTED = {FrameId.TORQUE_CMD, FrameId.CTRL_HEARTBEAT, FrameId.SIM_TIME,
             FrameId.KNEE_FEEDBACK, FrameId.ANKLE_FEEDBACK, FrameId.FOOT_LOAD,
             FrameId.SOCKET_IMU, FrameId.CTRL_CLF}


def bits(x: float) -> bytes:
    return struct.pack("<d", x)


# --------------------------------------------------------------------------- DBC


def test_dbc_frames_ids_senders():
    db = protocol.database()
    assert db is protocol.database()  # parsed once
    assert db.buses[0].baudrate == protocol.BITRATE == 500_000
    assert {m.frame_id: m.name for m in db.messages} == {
        0x010: "TorqueCmd", 0x020: "CtrlHeartbeat", 0x080: "SimTime",
        0x101: "KneeFeedback", 0x102: "AnkleFeedback", 0x110: "FootLoad",
        0x111: "SocketImu", 0x300: "CtrlStatus", 0x301: "CtrlRejects", 0x302: "CtrlDisturbance",
        0x303: "CtrlClf"}
    assert {int(i) for i in FrameId} == {m.frame_id for m in db.messages}
    for m in db.messages:
        assert m.length == 8 and not m.is_extended_frame and not m.is_fd
        expected = protocol.PLANT_TO_CTRL if m.senders == ["PLANT"] else protocol.CTRL_TO_PLANT
        assert m.frame_id in expected
    assert {i for i, s in protocol.frame_specs().items() if s.protected} == PROTECTED


def test_quantization_constants_match_dbc():
    spec = protocol.frame_spec
    for frame, sig, step, rng in [
        ("KneeFeedback", "KneeAngle", protocol.ANGLE_STEP, protocol.ANGLE_RANGE),
        ("AnkleFeedback", "AnkleAngle", protocol.ANGLE_STEP, protocol.ANGLE_RANGE),
        ("KneeFeedback", "KneeVelocity", protocol.VELOCITY_STEP, protocol.VELOCITY_RANGE),
        ("AnkleFeedback", "AnkleVelocity", protocol.VELOCITY_STEP, protocol.VELOCITY_RANGE),
        ("TorqueCmd", "KneeTorqueCmd", protocol.TORQUE_STEP, protocol.TORQUE_RANGE),
        ("TorqueCmd", "AnkleTorqueCmd", protocol.TORQUE_STEP, protocol.TORQUE_RANGE),
        ("FootLoad", "FootNormalLoad", protocol.LOAD_STEP, protocol.LOAD_RANGE),
        ("SocketImu", "SocketPitch", protocol.ANGLE_STEP, protocol.ANGLE_RANGE),
        ("CtrlClf", "ClfV", protocol.CLF_V_STEP, protocol.CLF_V_RANGE),
        ("CtrlClf", "ClfRho", protocol.CLF_RHO_STEP, protocol.CLF_RHO_RANGE),
    ]:
        s = spec(frame).signal(sig)
        assert (s.scale, s.offset, (s.minimum, s.maximum)) == (step, 0, rng)
        # the range fits the raw integer (clamping never overflows)
        raw = round(max(abs(s.minimum), abs(s.maximum)) / s.scale)
        assert raw < 2 ** (s.length - 1) if s.signed else raw == 2 ** s.length - 1


def test_bus_load_of_dbc_cycle_times():
    assert protocol.frame_bits() == 111 and protocol.frame_bits(worst_case=True) == 135
    # 6 frames every 2 ms, heartbeat 10 ms, 2 status frames 100 ms: 3120 frames/s
    assert protocol.bus_load() == pytest.approx(3120 * 111 / 500_000)
    assert protocol.bus_load(worst_case=True) == pytest.approx(3120 * 135 / 500_000)
    one_khz = {i: 1000.0 for i in PROTECTED - {FrameId.CTRL_HEARTBEAT}}
    assert protocol.bus_load(one_khz) > 1.0  # 1 kHz exchange does not fit 500 kbit/s


# --------------------------------------------------------------------------- CRC


def test_crc8_sae_j1850_vectors():
    # catalogue check value and the AUTOSAR CRC library examples for CRC-8/SAE-J1850
    assert crc8(b"123456789") == 0x4B
    for data, crc in [("00000000", 0x59), ("F20183", 0x37), ("0FAA0055", 0x79),
                      ("00FF5511", 0xB8), ("332255AABBCCDDEEFF", 0xCB), ("926B55", 0x8C),
                      ("FFFFFFFF", 0x74)]:
        assert crc8(bytes.fromhex(data)) == crc


def test_frame_checksum_covers_id_and_seven_bytes():
    m = codec.encode_torque(1.0, -1.0, 5)
    assert m.data[7] == frame_checksum(0x010, m.data)
    assert m.data[7] == crc8(bytes([0x10, 0x00]) + bytes(m.data[:7]))


def test_every_one_and_two_bit_error_is_detected():
    m = codec.encode_feedback(0.3, -1.0, 0.1, 2.0, 700.0, True, 9)[0]
    assert codec.decode(m).ok
    for k in (1, 2):
        for flips in itertools.combinations(range(64), k):
            data = bytearray(m.data)
            for b in flips:
                data[b // 8] ^= 1 << (b % 8)
            v = codec.decode(can.Message(arbitration_id=m.arbitration_id,
                                         is_extended_id=False, data=data))
            assert v.status is FrameStatus.BAD_CHECKSUM, flips


def test_payload_on_the_wrong_id_fails_the_checksum():
    knee = codec.encode_feedback(0.3, -1.0, 0.1, 2.0, 700.0, True, 9)[0]
    moved = can.Message(arbitration_id=FrameId.ANKLE_FEEDBACK, is_extended_id=False,
                        data=knee.data)
    assert codec.decode(moved).status is FrameStatus.BAD_CHECKSUM


# --------------------------------------------------------------------------- encode / decode


def test_feedback_round_trip_values():
    msgs = codec.encode_feedback(0.5, -1.25, -0.123456, 3.3, 812.34, True, 7,
                                 sim_time_us=123_456, timestamp=1.5)
    assert [m.arbitration_id for m in msgs] == [0x101, 0x102, 0x110, 0x080]  # no IMU
    assert all(m.dlc == 8 and len(m.data) == 8 and not m.is_extended_id for m in msgs)
    v = [codec.decode(m) for m in msgs]
    assert all(x.ok and x.counter == 7 and x.timestamp == 1.5 for x in v)
    assert v[0].value == codec.KneeFeedback(0.5, -1.25)
    assert v[1].value.angle == codec.quantize_angle(-0.123456)
    assert v[1].value.angle == pytest.approx(-0.12346, abs=1e-12)
    assert v[1].value.velocity == pytest.approx(3.3, abs=1e-12)
    assert v[2].value.load == pytest.approx(812.3, abs=1e-9) and v[2].value.contact == 1
    assert v[3].value == codec.SimTime(123_456)
    assert bytes(msgs[0].data).hex() == "50c3002ccfff07b7"  # a frozen reference frame


def test_torque_is_clamped_at_the_boundary_and_nan_refused():
    assert codec.decode(codec.encode_torque(7.0, -12.0, 0)).value == codec.TorqueCmd(5.0, -5.0, 1)
    assert codec.decode(codec.encode_torque(math.inf, -math.inf, 0)).value[:2] == (5.0, -5.0)
    assert codec.decode(codec.encode_torque(1.2345674, 0, 0, enable=False)).value == \
        codec.TorqueCmd(1.234567, 0.0, 0)
    with pytest.raises(ValueError, match=r"TorqueCmd\.AnkleTorqueCmd: NaN"):
        codec.encode_torque(1.0, math.nan, 0)
    with pytest.raises(ValueError, match=r"KneeFeedback\.KneeAngle: NaN"):
        codec.encode_feedback(math.nan, 0, 0, 0, 0, False, 0)
    assert codec.quantize_torque(np.array([-9.0, 9.0])).tolist() == [-5.0, 5.0]
    with pytest.raises(ValueError, match="NaN"):
        codec.quantize_angle(np.array([0.0, np.nan]))


def test_feedback_values_are_clamped_to_dbc_ranges():
    v = [codec.decode(m).value for m in
         codec.encode_feedback(4.0, -80.0, -3.3, 60.0, 5000.0, False, 1)]
    assert v[0] == (3.2, -50.0) and v[1] == (-3.2, 50.0) and v[2] == (3000.0, 0)


def test_heartbeat_status_rejects():
    hb = codec.decode(codec.encode_heartbeat(CtrlState.SAFE, 2**32 + 5, 17))
    assert hb.value == (CtrlState.SAFE, 5) and hb.value.state is CtrlState.SAFE
    assert hb.counter == 1
    with pytest.raises(ValueError, match="CtrlState"):
        codec.encode_heartbeat(4, 0, 0)
    status, rej = codec.encode_status(FaultFlag.QP_FAILED | FaultFlag.STALE_FEEDBACK,
                                      QpStatus.MAX_ITER, 12, 70_000, 3,
                                      {"bad_checksum": 5, FrameStatus.UNKNOWN_ID: 9999})
    s = codec.decode(status).value
    assert s.fault_flags == FaultFlag.QP_FAILED | FaultFlag.STALE_FEEDBACK
    assert s.qp_status is QpStatus.MAX_ITER
    assert (s.qp_iterations, s.fallback_count, int(s.active_constraints)) == (12, 65535, 3)
    assert codec.decode(rej).value == codec.CtrlRejects(5, 0, 0, 0, 4095)
    assert codec.decode(status).counter is None
    # an unknown QpStatus value from the wire is passed through as an int
    assert codec.decode(codec.encode_status(qp_status=9)[0]).value.qp_status == 9
    # the model-error coverage monitor: flag and a count saturating at 127
    assert (s.coverage_flag, s.coverage_count) == (0, 0)
    s = codec.decode(codec.encode_status(coverage_flag=True, coverage_count=5)[0]).value
    assert (s.coverage_flag, s.coverage_count) == (1, 5)
    s = codec.decode(codec.encode_status(coverage_count=10_000)[0]).value
    assert (s.coverage_flag, s.coverage_count) == (0, 127)
    assert codec.decode_cantools(codec.encode_status(coverage_flag=True)[0])["CoverageFlag"] == 1


def test_disturbance_frame():
    """CtrlDisturbance: the online model-error estimate, quantized as the DBC says (1e-3
    m/s^2, 1e-2 rad/s^2, 1e-4 in tau, 1 ms), clamped to its ranges; unprotected."""
    m = codec.encode_disturbance(0.1234, -5.678, 0.4321, True, True, 0.0314)
    v = codec.decode(m)
    assert v.ok and v.name == "CtrlDisturbance" and v.counter is None
    d = v.value
    assert d.dy1 == pytest.approx(0.123, abs=1e-9) and d.d2y2 == pytest.approx(-5.68, abs=1e-9)
    assert d.tau == pytest.approx(0.4321, abs=1e-9) and (d.valid, d.flag) == (1, 1)
    assert d.since_touchdown == pytest.approx(0.031, abs=1e-9)
    assert codec.decode_cantools(m)["DistD2y2"] == pytest.approx(-5.68)
    big = codec.decode(codec.encode_disturbance(1e3, -1e4, 9.0, False, False, 7.0)).value
    assert (big.dy1, big.d2y2, big.tau, big.since_touchdown) == pytest.approx(
        (32.0, -320.0, 3.2, 0.255))
    with pytest.raises(ValueError, match="NaN"):
        codec.encode_disturbance(math.nan, 0.0, 0.0, True, False, 0.0)


def test_clf_frame():
    """CtrlClf: V (step 1e-5) and rho (step 1e-3), dimensionless, >= 0, clamped to their
    24-bit ranges; None or non-finite is absent (valid bit 0, value 0); protected (counter
    and checksum like TorqueCmd); the cantools reference decodes the same bytes."""
    m = codec.encode_clf(0.0123456, 4.6891, 19, timestamp=0.25)
    v = codec.decode(m)
    assert v.ok and v.name == "CtrlClf" and v.counter == 3 and v.timestamp == 0.25
    c = v.value
    assert (c.v_valid, c.rho_valid) == (1, 1)
    assert bits(c.V) == bits(codec.quantize_clf_v(0.0123456))
    assert bits(c.rho) == bits(codec.quantize_clf_rho(4.6891))
    assert (c.V, c.rho) == pytest.approx((0.01235, 4.689), abs=1e-12)
    ref = codec.decode_cantools(m)
    assert (ref["ClfV"], ref["ClfRho"], ref["ClfVValid"], ref["ClfRhoValid"], ref["Counter"]) \
        == (c.V, c.rho, 1, 1, 3)
    assert m.data[7] == frame_checksum(FrameId.CTRL_CLF, m.data)
    assert codec.decode(codec.encode_clf(0.2, None, 0)).value == codec.CtrlClf(0.2, 0.0, 1, 0)
    assert codec.decode(codec.encode_clf(math.nan, math.inf, 0)).value == (0.0, 0.0, 0, 0)
    big = codec.decode(codec.encode_clf(1e9, 1e9, 0)).value
    assert (big.V, big.rho) == pytest.approx(protocol.CLF_V_RANGE[1:] + protocol.CLF_RHO_RANGE[1:])
    assert codec.decode(codec.encode_clf(-1e-12, -3.0, 0)).value == (0.0, 0.0, 1, 1)
    with pytest.raises(ValueError, match="rolling counter"):
        codec.encode_frame("CtrlClf", {"ClfV": 0.1, "ClfRho": 0.0, "ClfVValid": 1,
                                       "ClfRhoValid": 1})


def test_sim_time_wraps_at_2_to_32():
    assert codec.decode(codec.encode_sim_time(2**32 + 10, 3)).value.us == 10


def test_encode_frame_by_name_checks_signals():
    m = codec.encode_frame("FootLoad", {"FootNormalLoad": 10.0, "FootContact": 1}, 4)
    assert codec.decode(m).value == codec.FootLoad(10.0, 1)
    with pytest.raises(ValueError, match="missing signals"):
        codec.encode_frame("FootLoad", {"FootNormalLoad": 10.0}, 4)
    with pytest.raises(ValueError, match="rolling counter"):
        codec.encode_frame("FootLoad", {"FootNormalLoad": 10.0, "FootContact": 1})


def _random_values(spec, rng):
    vals = {}
    for s in spec.payload:
        if s.linear:
            kind = rng.integers(4)
            if kind == 0:  # exact half-step ties exercise round-half-to-even
                x = (rng.integers(-1000, 1000) + 0.5) * s.scale
            elif kind == 1:
                x = float(rng.choice([s.minimum, s.maximum]))
            else:
                x = float(rng.uniform(s.minimum, s.maximum))
        else:
            x = int(rng.integers(s.minimum, s.maximum + 1))
        vals[s.name] = x
    return vals


def test_fast_path_is_bit_identical_to_cantools():
    rng = np.random.default_rng(20201025)
    for spec in protocol.frame_specs().values():
        for _ in range(300):
            vals = _random_values(spec, rng)
            counter = int(rng.integers(0, 16))
            fast = codec.encode_frame(spec.frame_id, vals, counter)
            ref = codec.encode_cantools(spec.frame_id, vals, counter)
            assert bytes(fast.data) == bytes(ref.data), (spec.name, vals)
            a, b = codec.decode_signals(fast), codec.decode_cantools(fast)
            assert a.keys() == b.keys()
            for k in a:
                assert type(a[k]) is type(b[k])
                assert bits(a[k]) == bits(b[k]), (spec.name, k)


def test_quantize_is_what_the_decoder_sees():
    rng = np.random.default_rng(1)
    x = np.concatenate([rng.uniform(-4, 4, 500), (np.arange(-50, 50) + 0.5) * 1e-5])
    qa = codec.quantize_angle(x)
    qv = codec.quantize_velocity(x * 20)
    ql = codec.quantize_load(x * 900)
    for i in range(len(x)):
        k, _, ld = (codec.decode(m).value for m in codec.encode_feedback(
            x[i], x[i] * 20, 0.0, 0.0, x[i] * 900, True, 0))
        assert bits(k.angle) == bits(qa[i]) == bits(codec.quantize_angle(float(x[i])))
        assert bits(k.velocity) == bits(qv[i])
        assert bits(ld.load) == bits(ql[i])
        assert abs(k.angle - np.clip(x[i], -3.2, 3.2)) <= 0.5e-5 + 1e-15
    q = codec.quantize_angle(qa)
    assert np.array_equal(q, qa)  # idempotent


# --------------------------------------------------------------------------- checker


def _fb(counter, frame=0):
    return codec.encode_feedback(0.1, 0.2, 0.3, 0.4, 500.0, True, counter)[frame]


def test_checker_counter_sequence():
    ck = FrameChecker()
    seq = [0, 1, 1, 2, 5, 6, 15]
    got = [ck.check(_fb(c)).status for c in seq]
    assert got == [FrameStatus.OK, FrameStatus.OK, FrameStatus.DUPLICATE, FrameStatus.OK,
                   FrameStatus.BAD_COUNTER, FrameStatus.OK, FrameStatus.BAD_COUNTER]
    # counters wrap mod 16, per frame id (each id's session starts at counter 0)
    assert ck.check(_fb(0)).ok and ck.check(_fb(0, frame=1)).ok
    assert ck.counts[FrameStatus.OK] == 6 and ck.counts[FrameStatus.BAD_COUNTER] == 2
    assert ck.counts[FrameStatus.DUPLICATE] == 1 and ck.rejected == 3 and ck.lost == 0
    assert ck.resyncs == 2  # 5 -> 6 and 15 -> 0: two consecutive frames agreed
    ck.reset()
    assert ck.rejected == 0 and ck.check(_fb(0)).ok


def test_checker_max_gap_counts_lost_frames():
    ck = FrameChecker(max_gap=3, first=14)
    assert [ck.check(_fb(c)).status for c in (14, 1, 5)] == [
        FrameStatus.OK, FrameStatus.OK, FrameStatus.BAD_COUNTER]
    assert ck.lost == 2
    with pytest.raises(ValueError):
        FrameChecker(max_gap=0)
    with pytest.raises(ValueError):
        FrameChecker(first=16)


def test_checker_session_starts_at_the_expected_counter():
    """The first frame of a session must carry counter 0: an intruder's (or a stale
    sender's) frame with another counter does not set the sequence; a session whose first
    frame was lost synchronizes once two consecutive frames agree."""
    ck = FrameChecker()
    assert ck.check(_fb(7)).status == FrameStatus.BAD_COUNTER
    assert [ck.check(_fb(c)).status for c in (0, 1, 2)] == [FrameStatus.OK] * 3
    lost_first = FrameChecker()
    assert [lost_first.check(_fb(c)).status for c in (1, 2, 3)] == [
        FrameStatus.BAD_COUNTER, FrameStatus.OK, FrameStatus.OK]
    assert FrameChecker(first=None).check(_fb(9)).ok


def test_checker_a_stray_frame_never_invalidates_the_next_genuine_one():
    ck = FrameChecker()
    got = []
    for c in (0, 1, 2, 9, 3, 4, 13, 5):  # 9 and 13 from someone else
        got.append(ck.check(_fb(c)).status)
    assert got == [FrameStatus.OK] * 3 + [FrameStatus.BAD_COUNTER] + [FrameStatus.OK] * 2 \
        + [FrameStatus.BAD_COUNTER, FrameStatus.OK]
    assert ck.resyncs == 0 and ck.lost == 0


def test_checker_rejects_replayed_frames():
    """Copies of a recorded frame played back later: each rejected (bad counter or
    duplicate), the genuine stream goes on unharmed."""
    ck = FrameChecker()
    old = _fb(4)
    statuses = [ck.check(_fb(c)).status for c in range(0, 10)]
    assert statuses == [FrameStatus.OK] * 10
    assert [ck.check(old).status for _ in range(3)] == [FrameStatus.BAD_COUNTER] * 3
    assert ck.check(_fb(10)).ok and ck.check(_fb(11)).ok
    assert ck.check(_fb(11)).status == FrameStatus.DUPLICATE
    assert ck.resyncs == 0


def test_checker_classifies_every_bad_frame():
    good = _fb(0)
    ck = FrameChecker(accept=protocol.PLANT_TO_CTRL)
    cases = [
        (can.Message(arbitration_id=0x7FF, is_extended_id=False, data=bytes(8)), "unknown_id"),
        (can.Message(arbitration_id=0x101, is_extended_id=True, data=good.data), "unknown_id"),
        (can.Message(is_error_frame=True), "unknown_id"),
        (codec.encode_torque(1.0, 1.0, 0), "unknown_id"),  # right DBC, wrong direction
        (can.Message(arbitration_id=0x101, is_extended_id=False, data=good.data[:7]),
         "bad_length"),
        (can.Message(arbitration_id=0x101, is_extended_id=False, dlc=8,
                     is_remote_frame=True), "bad_length"),
        (can.Message(arbitration_id=0x101, is_extended_id=False, is_fd=True,
                     data=bytes(good.data) + bytes(4)), "bad_length"),
        (can.Message(arbitration_id=0x101, is_extended_id=False,
                     data=bytes(good.data[:7]) + bytes([good.data[7] ^ 1])), "bad_checksum"),
        (good, "ok"),
        (good, "duplicate"),
    ]
    for msg, want in cases:
        v = ck.check(msg)
        assert v.status == want, (msg, v)
        assert (v.value is not None) == (want == "ok")
    assert ck.counts == {FrameStatus.OK: 1, FrameStatus.DUPLICATE: 1,
                         FrameStatus.UNKNOWN_ID: 4, FrameStatus.BAD_LENGTH: 3,
                         FrameStatus.BAD_CHECKSUM: 1, FrameStatus.BAD_COUNTER: 0}
    _, rej = codec.encode_status(rejects=ck.counts)
    assert codec.decode(rej).value == codec.CtrlRejects(1, 0, 3, 1, 4)


def test_decode_never_raises_on_non_messages():
    for junk in (None, object(), 42, "frame"):
        v = codec.decode(junk)  # type: ignore[arg-type]
        assert v.status is FrameStatus.UNKNOWN_ID and not v.ok
    odd = _fb(0)
    odd.data = 12345  # type: ignore[assignment]
    assert codec.decode(odd).status is FrameStatus.BAD_LENGTH
    view = _fb(0)
    view.data = memoryview(bytes(view.data))  # type: ignore[assignment]
    assert codec.decode(view).ok


@settings(max_examples=400, deadline=None)
@given(fid=st.integers(0, 0x1FFFFFFF), ext=st.booleans(), data=st.binary(max_size=64),
       dlc=st.integers(0, 20), remote=st.booleans(), err=st.booleans(), fd=st.booleans())
def test_garbage_never_raises(fid, ext, data, dlc, remote, err, fd):
    msg = can.Message(arbitration_id=fid, is_extended_id=ext, data=data, dlc=dlc,
                      is_remote_frame=remote, is_error_frame=err, is_fd=fd)
    v = FrameChecker().check(msg)
    assert isinstance(v.status, FrameStatus)


@settings(max_examples=300, deadline=None)
@given(fid=st.sampled_from(sorted(int(i) for i in FrameId)), data=st.binary(min_size=8,
                                                                             max_size=8))
def test_random_payloads_on_known_ids(fid, data):
    v = codec.decode(can.Message(arbitration_id=fid, is_extended_id=False, data=data))
    if fid in PROTECTED:
        assert v.ok == (data[7] == frame_checksum(fid, data))
    else:
        assert v.ok
    if v.ok:
        ref = codec.decode_cantools(can.Message(arbitration_id=fid, data=data))
        assert list(v.value) == [ref[s.name] for s in protocol.frame_spec(fid).payload]


# --------------------------------------------------------------------------- light frames


def test_light_frames_are_the_messages_bytes():
    from bus_schemas.transport import frame

    assert frame.FRAME_LENGTH == protocol.FRAME_LENGTH and codec.Frame is frame.Frame
    rng = np.random.default_rng(22)
    for i in range(500):
        a = rng.uniform(-4, 4, 5) * (10.0 ** rng.integers(-6, 2))
        load = float(rng.uniform(-1500, 3500))
        pitch = [None, math.nan, float(a[4])][i % 3]
        kw = {"sim_time_us": int(rng.integers(0, 2**40)) if i % 4 else None,
              "socket_pitch": pitch, "timestamp": float(rng.uniform(0, 100))}
        args = (*map(float, a[:4]), load, bool(i % 2), int(rng.integers(0, 64)))
        msgs = codec.encode_feedback(*args, **kw)
        frames = codec.feedback_frames(*args, **kw)
        assert len(msgs) == len(frames)
        for m, f in zip(msgs, frames, strict=True):
            assert type(f) is codec.Frame and type(f.data) is bytes
            assert (f.timestamp, f.arbitration_id, f.data) == (
                m.timestamp, m.arbitration_id, bytes(m.data))
            assert f.to_message().equals(m, timestamp_delta=0.0)
    with pytest.raises(ValueError, match="NaN"):
        codec.feedback_frames(math.nan, 0, 0, 0, 0, True, 0)


def _same(a: codec.Verdict, b: codec.Verdict) -> None:
    assert (a.status, a.frame_id, a.name, a.counter, a.timestamp, a.detail) == (
        b.status, b.frame_id, b.name, b.counter, b.timestamp, b.detail)
    assert a.value == b.value and type(a.value) is type(b.value)


@settings(max_examples=400, deadline=None)
@given(fid=st.one_of(st.sampled_from(sorted(int(i) for i in FrameId)),
                     st.integers(0, 0x7FF)),
       data=st.one_of(st.binary(min_size=8, max_size=8), st.binary(max_size=12)),
       ts=st.floats(allow_nan=False))
def test_decode_frame_equals_decode(fid, data, ts):
    f = codec.Frame(ts, fid, data)
    m = can.Message(timestamp=ts, arbitration_id=fid, is_extended_id=False, data=data,
                    dlc=8)
    _same(codec.decode_frame(f), codec.decode(m))


def corrupted(rng: np.random.Generator, f: codec.Frame) -> tuple[bytearray, int]:
    """A frame's data and id, left as they are or (7 % of the time) a bit flipped, the data
    cut short or the id replaced by an unknown or unaccepted one."""
    r = rng.random()
    data, fid = bytearray(f.data), f.arbitration_id
    if r < 0.03:
        data[int(rng.integers(0, 8))] ^= 1 << int(rng.integers(0, 8))
    elif r < 0.05:
        data = data[:int(rng.integers(0, 8))]
    elif r < 0.07:
        fid = int(rng.choice([0x010, 0x7FF, 0x300, 0x5]))
    return data, fid


def test_checker_gives_the_same_verdicts_for_frames_and_messages():
    """Every class, with counters in and out of sequence, replays, corruptions."""
    rng = np.random.default_rng(5)
    a, b = FrameChecker(accept=protocol.PLANT_TO_CTRL), FrameChecker(
        accept=protocol.PLANT_TO_CTRL)
    for k in range(3000):
        counter = k % 16 if rng.random() > 0.1 else int(rng.integers(0, 16))
        fr = codec.feedback_frames(*rng.uniform(-1, 1, 4), 100.0, True, counter,
                                   sim_time_us=k, timestamp=k * 1e-3)
        for f in fr:
            data, fid = corrupted(rng, f)
            f2 = codec.Frame(f.timestamp, fid, bytes(data))
            m = can.Message(timestamp=f.timestamp, arbitration_id=fid,
                            is_extended_id=False, data=data, dlc=8)
            _same(a.check(f2), b.check(m))
    assert a.counts == b.counts and a.counts[FrameStatus.OK] > 6000
    assert all(a.counts[s] for s in FrameStatus)
    assert (a.lost, a.resyncs) == (b.lost, b.resyncs)


def test_checker_check_all_is_check_of_each_frame():
    """FrameChecker.check_all over a cycle's frames at once: the same verdicts, counts,
    losses and resynchronizations as check() frame by frame, over every class (corrupted,
    short, unknown or unaccepted ids, counters out of sequence and replayed, unprotected
    frames, can.Messages mixed in)."""
    rng = np.random.default_rng(11)
    a, b = FrameChecker(), FrameChecker()
    c, d = FrameChecker(accept=protocol.PLANT_TO_CTRL), FrameChecker(
        accept=protocol.PLANT_TO_CTRL)
    for k in range(3000):
        counter = k % 16 if rng.random() > 0.1 else int(rng.integers(0, 16))
        fr = codec.feedback_frames(*rng.uniform(-1, 1, 4), 100.0, True, counter,
                                   sim_time_us=k, socket_pitch=0.1, timestamp=k * 1e-3)
        fr.append(codec.disturbance_frame(0.1, 0.2, 0.3, True, False, 0.01,
                                          timestamp=k * 1e-3))
        sample: list = []
        for f in fr:
            data, fid = corrupted(rng, f)
            if rng.random() < 0.05:
                sample.append(can.Message(timestamp=f.timestamp, arbitration_id=fid,
                                          is_extended_id=False, data=data, dlc=8))
            else:
                sample.append(codec.Frame(f.timestamp, fid, bytes(data)))
            if rng.random() < 0.02:
                sample.append(sample[-1])  # replayed
        for x, y in ((a, b), (c, d)):
            got = x.check_all(sample)
            assert len(got) == len(sample)
            for v, m in zip(got, sample, strict=True):
                _same(v, y.check(m))
    for x, y in ((a, b), (c, d)):
        assert x.counts == y.counts and (x.lost, x.resyncs) == (y.lost, y.resyncs)
        assert all(x.counts[s] for s in FrameStatus) and x.counts[FrameStatus.OK] > 9000


def test_generated_decoders_equal_the_layout_loop_and_cantools():
    """The per-frame decoders generated from the DBC
    (bus_schemas.transport.codec.fastcodec), over random data of every frame (most with a
    wrong checksum, the rest with a right one): the same classification as the CRC rule and
    the same values, bit for bit, as the layout loop (decode_signals) and as cantools."""
    rng = np.random.default_rng(77)
    for fid in (int(i) for i in FrameId):
        names = [s.name for s in protocol.frame_spec(fid).payload]
        for i in range(2000):
            data = bytearray(rng.integers(0, 256, 8, dtype=np.uint8).tobytes())
            if i % 2:
                data[7] = frame_checksum(fid, data)
            m = can.Message(arbitration_id=fid, is_extended_id=False, data=data)
            v = codec.decode(m)
            assert v.ok == (fid not in PROTECTED or data[7] == frame_checksum(fid, data))
            if not v.ok:
                assert v.status is FrameStatus.BAD_CHECKSUM
                continue
            loop, ref = codec.decode_signals(m), codec.decode_cantools(m)
            for name, x in zip(names, v.value, strict=True):
                assert bits(x) == bits(loop[name]) == bits(ref[name]), (fid, name)
            if fid in PROTECTED:
                assert v.counter == loop["Counter"] == ref["Counter"]


def test_light_encoders_are_the_message_encoders():
    rng = np.random.default_rng(3)
    for k in range(300):
        a, b = (float(x) for x in rng.uniform(-7, 7, 2))
        ts = float(rng.uniform(0, 9))
        pairs = [(codec.encode_torque(a, b, k, enable=bool(k % 2), timestamp=ts),
                  codec.torque_frame(a, b, k, enable=bool(k % 2), timestamp=ts)),
                 (codec.encode_heartbeat(k % 4, k * 977, k, timestamp=ts),
                  codec.heartbeat_frame(k % 4, k * 977, k, timestamp=ts)),
                 (codec.encode_disturbance(a * 9, b * 90, a / 2, k % 2, k % 3, b / 20,
                                           timestamp=ts),
                  codec.disturbance_frame(a * 9, b * 90, a / 2, k % 2, k % 3, b / 20,
                                          timestamp=ts)),
                 (codec.encode_clf(abs(a) * 30, None if k % 3 == 0 else b * 3000, k,
                                   timestamp=ts),
                  codec.clf_frame(abs(a) * 30, None if k % 3 == 0 else b * 3000, k,
                                  timestamp=ts))]
        for m, f in pairs:
            assert (f.timestamp, f.arbitration_id, f.data) == (
                m.timestamp, m.arbitration_id, bytes(m.data))
    with pytest.raises(ValueError, match="NaN"):
        codec.torque_frame(math.nan, 0.0, 0)
    with pytest.raises(ValueError, match="CtrlState"):
        codec.heartbeat_frame(9, 0, 0)
