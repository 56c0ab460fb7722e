"""ZenohBus: wire format, in-process pairs of sessions over TCP loopback, the python-can
entry point, and a real second OS process echoing frames back."""

from __future__ import annotations

import os
import statistics
import struct
import subprocess
import sys
import textwrap
import threading
import time
import tomllib
from pathlib import Path
from typing import Any

import can
import pytest
import zenoh
from hypothesis import given, settings
from hypothesis import strategies as st

from bus_schemas.transport import codec
from bus_schemas.transport.bus_config import FrameReader, send_frames
from bus_schemas.transport.codec import FrameChecker
from bus_schemas.transport.keys import Direction
from bus_schemas.transport.protocol import CTRL_TO_PLANT, PLANT_TO_CTRL, CtrlState
from bus_schemas.transport.wire import (
    pack_batch,
    pack_message,
    unpack_frames,
    unpack_message,
    unpack_payload,
)
from bus_schemas.transport.zenoh_can import ZenohBus, parse_channel
from bus_schemas.transport.zenoh_config import loopback_endpoint

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(params=["default", "low_latency+poll"])
def pair(request):
    """A plant bus listening on a free loopback port and a controller bus connected to it,
    each with its own zenoh session; once with zenoh's normal transport and blocking
    receives, once with the low-latency transport and a polling receive (as in a lockstep
    co-simulation)."""
    ep = loopback_endpoint()
    kw = {} if request.param == "default" else {"low_latency": True, "poll_us": 300.0}
    plant = ZenohBus("t1/plant", listen=ep, **kw)
    ctrl = ZenohBus("t1/ctrl", connect=ep, **kw)
    try:
        assert plant.wait_for_peer(5.0) and ctrl.wait_for_peer(5.0)
        yield plant, ctrl
    finally:
        ctrl.shutdown()
        plant.shutdown()


def test_wire_format_round_trip():
    msgs = [
        can.Message(timestamp=12.25, arbitration_id=0x101, is_extended_id=False,
                    data=bytes(range(8))),
        can.Message(timestamp=1.0, arbitration_id=0x1ABCDEF0, is_extended_id=True, data=b""),
        can.Message(timestamp=2.0, arbitration_id=0x55, is_extended_id=False,
                    is_remote_frame=True, dlc=8),
        can.Message(timestamp=3.0, arbitration_id=0x66, is_fd=True, bitrate_switch=True,
                    error_state_indicator=True, data=bytes(range(64))),
        can.Message(timestamp=4.0, is_error_frame=True),
    ]
    for m in msgs:
        p = pack_message(m)
        assert len(p) == 15 + len(m.data)
        r = unpack_message(p, "ch")
        assert r is not None and r.equals(m, timestamp_delta=0.0, check_channel=False)
        assert r.timestamp == m.timestamp and r.is_rx and r.channel == "ch"
    assert len(pack_message(msgs[0])) == 23
    assert unpack_message(pack_message(msgs[0], 99.5)).timestamp == 99.5


def test_wire_format_rejects_garbage():
    good = pack_message(can.Message(arbitration_id=0x10, data=bytes(8)))
    for bad in (b"", b"\x01" * 14, b"\x02" + good[1:], good + bytes(60),
                good[:5] + b"\xff\xff\xff\xff" + good[9:]):
        assert unpack_message(bad) is None


def test_batch_wire_format_round_trip():
    msgs = codec.encode_feedback(0.1, -0.2, 0.3, 0.0, 650.0, True, 7, sim_time_us=7000,
                                 timestamp=0.007)
    fd = can.Message(timestamp=3.0, arbitration_id=0x66, is_fd=True, data=bytes(range(64)))
    p = pack_batch([*msgs, fd])
    assert p[:2] == bytes((2, 5)) and len(p) == 2 + 4 * 24 + (1 + 15 + 64)
    got, bad = unpack_payload(p, "ch")
    assert bad == 0 and len(got) == 5
    for a, b in zip(got, [*msgs, fd], strict=True):
        assert a.equals(b, timestamp_delta=0.0, check_channel=False) and a.is_rx
    assert pack_batch(msgs[:2], 9.5)[3:12] == pack_message(msgs[0], 9.5)[:9]
    # a single frame is the single-frame form; both are understood
    assert unpack_payload(pack_message(msgs[0]))[0][0].arbitration_id == 0x101
    with pytest.raises(ValueError, match="batch"):
        pack_batch([])


def test_batch_wire_format_rejects_garbage():
    p = pack_batch(codec.encode_feedback(0.1, 0.0, 0.0, 0.0, 1.0, False, 1))
    for bad in (p[:-1], p + b"\x00", bytes((2, 5)) + p[2:], bytes((2, 0)), b"\x02",
                bytes((2, 1, 200)) + bytes(20)):
        assert unpack_payload(bad) == ([], 1), bad
    inner = bytearray(p)
    inner[2 + 1] = 9  # the first frame's own version byte
    frames, bad = unpack_payload(bytes(inner))
    assert bad == 1 and [m.arbitration_id for m in frames] == [0x102, 0x110]


def _fields(m: Any) -> tuple[Any, ...]:
    return (m.timestamp, m.arbitration_id, bytes(m.data), m.dlc, m.is_extended_id,
            m.is_remote_frame, m.is_error_frame, m.is_fd, m.bitrate_switch,
            m.error_state_indicator)


def test_light_frames_pack_and_unpack_as_messages():
    frames = codec.feedback_frames(0.1, -0.2, 0.3, 0.0, 650.0, True, 7, sim_time_us=7000,
                                   socket_pitch=0.01, timestamp=0.007)
    msgs = [f.to_message() for f in frames]
    for ts in (None, 9.5):
        assert pack_batch(frames, ts) == pack_batch(msgs, ts)
    # a fault plan's odd frame among light ones: the general path, same bytes
    odd = can.Message(timestamp=0.007, arbitration_id=0x101, dlc=7, data=bytes(7))
    assert pack_batch([odd, *frames]) == pack_batch([odd, *msgs])
    p = pack_batch(frames)
    got, bad = unpack_frames(p, "ch")
    ref, bad_ref = unpack_payload(p, "ch")
    assert bad == bad_ref == 0 and all(type(g) is codec.Frame for g in got)
    assert [_fields(g) for g in got] == [_fields(m) for m in ref]
    assert [_fields(g) for g in unpack_frames(pack_message(msgs[0]))[0]] == [
        _fields(msgs[0])]


@settings(max_examples=400, deadline=None)
@given(frames=st.lists(st.tuples(st.floats(), st.integers(0, 0x1FFFFFFF),
                                 st.integers(0, 63), st.binary(min_size=8, max_size=8),
                                 st.integers(0, 3)), min_size=1, max_size=8),
       cut=st.integers(0, 4))
def test_unpack_frames_agrees_with_unpack_payload(frames, cut):
    """Random batches of 8-byte frames (any id, flags, NaN timestamps, wrong versions,
    truncated): the same frames, fields and malformed count as the general path."""
    parts = [bytes((2, len(frames)))]
    for ts, aid, flags, data, ver in frames:
        body = struct.pack("<BdIBB", ver if ver < 3 else 1, ts, aid, flags if ver else 0,
                           8) + data
        parts += [bytes((len(body),)), body]
    p = b"".join(parts)
    p = p[:len(p) - cut]
    got, bad = unpack_frames(p)
    ref, bad_ref = unpack_payload(p)
    assert bad == bad_ref
    assert [_fields(g) if g.timestamp == g.timestamp else None for g in got] == [
        _fields(m) if m.timestamp == m.timestamp else None for m in ref]


def test_recv_frames_and_the_frame_reader(pair):
    plant, ctrl = pair
    reader = FrameReader(ctrl)
    for k in range(20):
        cycle = codec.feedback_frames(0.01 * k, 0.0, 0.0, 0.0, 600.0, True, k,
                                      sim_time_us=1000 * k, timestamp=k * 1e-3)
        send_frames(plant, cycle)
        got = [reader.recv(2.0) for _ in cycle]
        assert got == cycle
    assert reader.recv(0.05) is None and ctrl.recv_frames(0.01) == []
    # a wake-up, a foreign key or a malformed payload does not cut the wait short (as
    # python-can's recv); a frame after them is returned
    plant.session.put("hpcosim/run/t1/can/tx/wake/someone", b"")
    plant.session.put("hpcosim/run/t1/can/tx", b"not a frame")
    t0 = time.monotonic()
    assert ctrl.recv_frames(0.2) == [] and time.monotonic() - t0 >= 0.19
    plant.session.put("hpcosim/run/t1/can/tx", b"not a frame")
    send_frames(plant, codec.feedback_frames(0.1, 0.0, 0.0, 0.0, 1.0, True, 0))
    assert [m.arbitration_id for m in ctrl.recv_frames(2.0)] == [0x101, 0x102, 0x110]
    # frames a recv left queued come first; filters apply
    send_frames(plant, codec.feedback_frames(0.1, 0.0, 0.0, 0.0, 1.0, True, 1,
                                             sim_time_us=1))
    assert ctrl.recv(2.0).arbitration_id == 0x101
    assert [m.arbitration_id for m in ctrl.recv_frames(1.0)] == [0x102, 0x110, 0x080]
    ctrl.set_filters([{"can_id": 0x110, "can_mask": 0x7FF}])
    send_frames(plant, codec.feedback_frames(0.1, 0.0, 0.0, 0.0, 1.0, True, 2))
    assert [m.arbitration_id for m in ctrl.recv_frames(2.0)] == [0x110]
    ctrl.set_filters(None)
    # a plain python-can bus: frame by frame, light frames sent as messages
    tx = can.Bus(interface="virtual", channel="reader")
    rx = can.Bus(interface="virtual", channel="reader")
    try:
        send_frames(tx, codec.feedback_frames(0.1, 0.0, 0.0, 0.0, 1.0, True, 3))
        r = FrameReader(rx)
        assert [r.recv(1.0).arbitration_id for _ in range(3)] == [0x101, 0x102, 0x110]
    finally:
        tx.shutdown()
        rx.shutdown()


def test_send_batch_arrives_frame_by_frame_in_order(pair):
    plant, ctrl = pair
    for k in range(30):
        cycle = codec.encode_feedback(0.01 * k, 0.0, 0.0, 0.0, 600.0, True, k,
                                      sim_time_us=1000 * k, timestamp=k * 1e-3)
        plant.send_batch(cycle)
        got = [ctrl.recv(2.0) for _ in range(4)]
        assert [m.arbitration_id for m in got] == [0x101, 0x102, 0x110, 0x080]
        assert [bytes(m.data) for m in got] == [bytes(m.data) for m in cycle]
        send_frames(ctrl, [codec.encode_heartbeat(CtrlState.RUNNING, k, k),
                           codec.encode_torque(0.1, 0.2, k, timestamp=k * 1e-3)])
        hb, tq = plant.recv(2.0), plant.recv(2.0)
        assert (hb.arbitration_id, tq.arbitration_id) == (0x020, 0x010)
        assert tq.timestamp == k * 1e-3
    send_frames(ctrl, [])  # nothing to send: nothing sent
    ctrl.send_batch([])
    assert plant.recv(0.05) is None
    assert plant.rx_malformed == ctrl.rx_malformed == 0


def test_send_frames_on_a_plain_python_can_bus():
    """Buses without send_batch (any python-can interface) get the frames one by one."""
    tx = can.Bus(interface="virtual", channel="send-frames")
    rx = can.Bus(interface="virtual", channel="send-frames")
    try:
        cycle = codec.encode_feedback(0.1, 0.0, 0.0, 0.0, 1.0, True, 3, sim_time_us=3)
        send_frames(tx, cycle)
        assert [rx.recv(1.0).arbitration_id for _ in cycle] == [0x101, 0x102, 0x110, 0x080]
    finally:
        tx.shutdown()
        rx.shutdown()


def test_polling_receive_honours_timeouts():
    ep = loopback_endpoint()
    with ZenohBus("t6/plant", listen=ep, poll_us=2000.0) as plant, \
            ZenohBus("t6/ctrl", connect=ep, poll_us=2000.0) as ctrl:
        assert plant.wait_for_peer(5.0)
        t0 = time.monotonic()
        assert ctrl.recv(0.0005) is None  # poll budget cut to the timeout
        assert ctrl.recv(0.05) is None  # polls 2 ms, then blocks for the rest
        assert 0.04 < time.monotonic() - t0 < 2.0
        plant.send_batch(codec.encode_feedback(0.1, 0.0, 0.0, 0.0, 1.0, True, 1,
                                               sim_time_us=1))
        assert [ctrl.recv(2.0).arbitration_id for _ in range(4)] == [0x101, 0x102, 0x110,
                                                                     0x080]


def test_channel_roles():
    assert parse_channel("r/plant") == ("r", Direction.TX, (Direction.RX,))
    assert parse_channel("r/ctrl") == ("r", Direction.RX, (Direction.TX,))
    assert parse_channel("r/rx:tx") == ("r", Direction.RX, (Direction.TX,))
    assert parse_channel("r/monitor") == ("r", None, (Direction.TX, Direction.RX))
    for bad in ("plant", "r/tx:tx", "r/up", "r/tx", "a*/plant"):
        with pytest.raises(ValueError):
            parse_channel(bad)


def test_plant_and_controller_exchange_frames(pair):
    plant, ctrl = pair
    ck_ctrl, ck_plant = FrameChecker(accept=PLANT_TO_CTRL), FrameChecker(accept=CTRL_TO_PLANT)
    for k in range(20):
        for m in codec.encode_feedback(0.01 * k, -0.5, 0.2, 0.0, 600.0 + k, k % 2 == 0, k,
                                       sim_time_us=1000 * k, timestamp=k * 1e-3):
            plant.send(m)
        got = [ctrl.recv(2.0) for _ in range(4)]
        verdicts = [ck_ctrl.check(m) for m in got]
        assert all(v.ok for v in verdicts), verdicts
        assert [m.timestamp for m in got] == [k * 1e-3] * 4  # sender's time kept
        assert verdicts[0].value.angle == codec.quantize_angle(0.01 * k)
        assert verdicts[2].value == codec.FootLoad(codec.quantize_load(600.0 + k), 1 - k % 2)
        assert verdicts[3].value.us == 1000 * k
        ctrl.send(codec.encode_torque(0.1 * k, -0.1 * k, k))
        ctrl.send(codec.encode_heartbeat(CtrlState.RUNNING, k, k))
        t, hb = ck_plant.check(plant.recv(2.0)), ck_plant.check(plant.recv(2.0))
        assert t.value.knee == codec.quantize_torque(0.1 * k) and hb.value.tick == k
    assert ck_ctrl.counts["ok"] == 80 and ck_ctrl.rejected == 0
    assert ck_plant.counts["ok"] == 40 and ck_plant.rejected == 0
    assert plant.rx_malformed == ctrl.rx_malformed == 0


def test_malformed_payloads_and_foreign_keys_are_skipped(pair):
    plant, ctrl = pair
    pub = plant.session.declare_publisher("hpcosim/run/t1/can/tx")
    try:
        pub.put(b"not a frame")
        plant.session.put("hpcosim/run/t1/can/tx/wake/someone", b"")
        plant.send(codec.encode_sim_time(9, 0))
        got = []
        while (m := ctrl.recv(0.5)) is not None:  # the three may arrive in any order
            got.append(codec.decode(m).value.us)
        assert got == [9] and ctrl.rx_malformed == 1
    finally:
        pub.undeclare()


@pytest.mark.serial  # all 40 frames must arrive within the 0.3 s sleep (wall time)
def test_full_receive_ring_drops_the_oldest_frames():
    ep = loopback_endpoint()
    with ZenohBus("t5/plant", listen=ep) as plant, \
            ZenohBus("t5/ctrl", connect=ep, rx_queue_size=8) as ctrl:
        assert plant.wait_for_peer(5.0)
        for k in range(40):
            plant.send(codec.encode_sim_time(k, k))
        time.sleep(0.3)
        got = []
        while (m := ctrl.recv(0.2)) is not None:
            got.append(codec.decode(m).value.us)
    assert got == list(range(32, 40))


def test_shutdown_unblocks_a_receiver_in_another_thread(pair):
    _, ctrl = pair
    errors: list[BaseException] = []

    def blocked() -> None:
        try:
            ctrl.recv()  # no timeout
        except can.CanOperationError as e:
            errors.append(e)

    th = threading.Thread(target=blocked)
    th.start()
    time.sleep(0.3)
    ctrl.shutdown()
    th.join(5.0)
    assert not th.is_alive() and len(errors) == 1


def test_recv_timeout_filters_and_own_messages(pair):
    plant, ctrl = pair
    t0 = time.monotonic()
    assert ctrl.recv(0.05) is None and ctrl.recv(0) is None
    assert 0.04 < time.monotonic() - t0 < 2.0
    ctrl.set_filters([{"can_id": 0x110, "can_mask": 0x7FF}])
    for m in codec.encode_feedback(0.1, 0.1, 0.1, 0.1, 100.0, True, 0):
        plant.send(m)
    m = ctrl.recv(2.0)
    assert m is not None and m.arbitration_id == 0x110
    assert ctrl.recv(0.05) is None
    ctrl.set_filters(None)
    own = ZenohBus("t1/monitor", session=ctrl.session)  # shares ctrl's session
    try:
        with pytest.raises(can.CanOperationError, match="monitor"):
            own.send(codec.encode_torque(0, 0, 0))
        echo = ZenohBus("t2/plant", receive_own_messages=True, stamp=True)
        try:
            echo.send(codec.encode_torque(1.0, 2.0, 3))
            back = echo.recv(1.0)
            assert back is not None and not back.is_rx
            assert abs(back.timestamp - time.time()) < 5.0
            assert codec.decode(back).value == codec.TorqueCmd(1.0, 2.0, 1)
            echo.send_batch([codec.encode_sim_time(1, 1), codec.encode_sim_time(2, 2)])
            assert [codec.decode(echo.recv(1.0)).value.us for _ in range(2)] == [1, 2]
        finally:
            echo.shutdown()
        # the monitor sees both directions
        plant.send(codec.encode_sim_time(5, 1))
        ctrl.send(codec.encode_torque(0.5, 0.5, 1))
        seen = {own.recv(2.0).arbitration_id, own.recv(2.0).arbitration_id}
        assert seen == {0x080, 0x010}
    finally:
        own.shutdown()
    assert not ctrl.session.is_closed()  # a borrowed session stays open


def test_shutdown_closes_session_and_liveliness(pair):
    plant, ctrl = pair
    assert plant.peer_alive("ctrl") and ctrl.peer_alive("plant")
    sub = plant.session.liveliness().declare_subscriber("hpcosim/run/t1/ctrl/alive",
                                                        zenoh.handlers.FifoChannel(8))
    ctrl.shutdown()
    assert ctrl.session.is_closed()
    with pytest.raises(can.CanOperationError):
        ctrl.send(codec.encode_torque(0, 0, 0))
    with pytest.raises(can.CanOperationError):
        ctrl.recv(0.01)
    ctrl.shutdown()  # idempotent
    deadline = time.monotonic() + 5
    sample = None
    while sample is None and time.monotonic() < deadline:
        sample = sub.try_recv()
        time.sleep(0.005)
    assert sample is not None and sample.kind == zenoh.SampleKind.DELETE
    assert not plant.peer_alive("ctrl", timeout=0.5)


def test_entry_point_is_declared():
    meta = tomllib.loads((ROOT / "pyproject.toml").read_text())
    eps = meta["project"]["entry-points"]["can.interface"]
    assert eps == {"zenoh": "bus_schemas.transport.zenoh_can:ZenohBus"}
    assert "*.dbc" in meta["tool"]["setuptools"]["package-data"]["bus_schemas"]


@pytest.mark.skipif("zenoh" not in can.interfaces.BACKENDS,
                    reason="the can.interface entry point appears after (re)installing hpcosim")
def test_can_bus_interface_zenoh_installed():
    ep = loopback_endpoint()
    with can.Bus(interface="zenoh", channel="t3/plant", listen=ep) as plant, \
            can.Bus(interface="zenoh", channel="t3/ctrl", connect=ep) as ctrl:
        assert isinstance(plant, ZenohBus) and plant.wait_for_peer(5.0)
        plant.send(codec.encode_sim_time(42, 0))
        assert codec.decode(ctrl.recv(2.0)).value.us == 42


def test_can_bus_finds_the_entry_point_in_a_fresh_process(tmp_path):
    """python-can's real discovery path: a dist-info with the declared entry point on
    sys.path of a fresh interpreter (what an install provides), then can.Bus(...)."""
    eps = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["entry-points"]
    dist = tmp_path / "hpcosim_ep_probe-0.0.dist-info"
    dist.mkdir()
    (dist / "METADATA").write_text("Metadata-Version: 2.1\nName: hpcosim-ep-probe\n"
                                   "Version: 0.0\n")
    (dist / "entry_points.txt").write_text(
        "[can.interface]\n" + "".join(f"{k} = {v}\n" for k, v in
                                      eps["can.interface"].items()))
    code = textwrap.dedent("""
        import can
        from bus_schemas.transport import codec
        from bus_schemas.transport.zenoh_config import loopback_endpoint
        ep = loopback_endpoint()
        with can.Bus(interface="zenoh", channel="t4/plant", listen=ep) as p, \\
                can.Bus(interface="zenoh", channel="t4/ctrl", connect=ep) as c:
            assert p.wait_for_peer(5.0)
            p.send(codec.encode_sim_time(77, 0))
            print(type(p).__name__, codec.decode(c.recv(2.0)).value.us)
    """)
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(tmp_path), str(ROOT)])}
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True,
                         text=True, timeout=60)
    assert out.returncode == 0, out.stderr
    assert out.stdout.split() == ["ZenohBus", "77"]


def test_cross_process_echo():
    """A second OS process (controller role) echoes every frame back over zenoh."""
    ep = loopback_endpoint()
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    n = 300
    with ZenohBus("xproc/plant", listen=ep) as plant:
        proc = subprocess.Popen([sys.executable, str(ROOT / "tests" / "bus_echo_node.py"),
                                 "xproc", ep], stdout=subprocess.PIPE, text=True, env=env)
        try:
            assert proc.stdout is not None
            assert proc.stdout.readline().strip() == "ready"
            assert plant.wait_for_peer(10.0) and plant.peer_alive("ctrl")
            checker = FrameChecker()
            rtt = []
            for k in range(n):
                m = codec.encode_torque(0.01 * k, -0.01 * k, k, timestamp=k * 1e-3)
                t0 = time.perf_counter()
                plant.send(m)
                back = plant.recv(5.0)
                rtt.append(time.perf_counter() - t0)
                assert back is not None and bytes(back.data) == bytes(m.data)
                assert back.timestamp == k * 1e-3
                assert checker.check(back).ok
            plant.send(can.Message(arbitration_id=0x7FF, is_extended_id=False))
            assert proc.stdout.readline().strip() == f"done {n}"
            assert proc.wait(10) == 0
        finally:
            if proc.poll() is None:
                proc.kill()
                proc.wait()
    assert checker.counts["ok"] == n
    med = statistics.median(rtt[20:]) * 1e6
    print(f"\nZenohBus cross-process round trip: median {med:.0f} us over {n - 20} frames")


def test_liveliness_through_the_bus_api():
    """The nodes' liveliness without reaching into the zenoh session: a node opened with
    ``declare_alive=False`` says it is alive when ready (``announce_alive``); the other
    watches it (``watch_peer``: polled or called back) and sees it come and go."""
    ep = loopback_endpoint()
    seen: list[bool] = []
    changed = threading.Event()

    def on_change(alive: bool) -> None:
        seen.append(alive)
        changed.set()

    with ZenohBus("t9/plant", listen=ep) as plant:
        ctrl = ZenohBus("t9/ctrl", connect=ep, declare_alive=False)
        polled = plant.watch_peer()
        called = plant.watch_peer(on_change)
        try:
            time.sleep(0.2)
            assert polled.poll() == [] and seen == []  # not alive yet
            ctrl.announce_alive()
            ctrl.announce_alive()  # idempotent
            assert changed.wait(5.0) and seen == [True]
            deadline = time.monotonic() + 5.0
            got: list[bool] = []
            while not got and time.monotonic() < deadline:
                got = polled.poll()
                time.sleep(0.01)
            assert got == [True]
            back = ctrl.watch_peer()  # the controller watches the plant, alive already
            deadline = time.monotonic() + 5.0
            got = []
            while not got and time.monotonic() < deadline:
                got = back.poll()
                time.sleep(0.01)
            back.close()
            assert got == [True]
            changed.clear()
            ctrl.shutdown()
            assert changed.wait(5.0) and seen == [True, False]
        finally:
            polled.close()
            called.close()
        with ZenohBus("t9/monitor", connect=ep) as monitor, \
                pytest.raises(ValueError, match="monitor"):
            monitor.watch_peer()
