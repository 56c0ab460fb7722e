"""Zenoh key expressions and the loopback-only session configuration."""

from __future__ import annotations

import json
import time

import pytest
import zenoh

from bus_schemas.transport import keys
from bus_schemas.transport.keys import Direction
from bus_schemas.transport.zenoh_can import publisher_matched
from bus_schemas.transport.zenoh_config import (
    ZenohMode,
    free_tcp_port,
    is_loopback_endpoint,
    loopback_endpoint,
    make_config,
)


def test_keys_layout():
    assert keys.can_key("r1", Direction.TX) == "hpcosim/run/r1/can/tx"
    assert keys.can_key("r1", "rx") == "hpcosim/run/r1/can/rx"
    assert keys.can_any_key("r1") == "hpcosim/run/r1/can/*"
    assert keys.ctrl_alive_key("r1") == "hpcosim/run/r1/ctrl/alive"
    assert keys.plant_alive_key("r1") == "hpcosim/run/r1/plant/alive"
    assert keys.parse_can_key("hpcosim/run/2024-01-02_a.b/can/tx") == ("2024-01-02_a.b",
                                                                     Direction.TX)
    assert Direction.TX.opposite is Direction.RX
    for k in ("hpcosim/run/r1/can/tx", keys.can_any_key("r1"), keys.ctrl_alive_key("r1")):
        zenoh.KeyExpr(k)  # valid zenoh key expressions
    assert zenoh.KeyExpr(keys.can_any_key("r1")).intersects(zenoh.KeyExpr(
        keys.can_key("r1", "rx")))


@pytest.mark.parametrize("bad", ["", "a/b", "a*", "$x", "a?b", "a#b", "..", "a b", "x" * 129])
def test_bad_run_ids_are_refused(bad):
    with pytest.raises(ValueError, match="run id"):
        keys.can_key(bad, "tx")


def test_parse_can_key_refuses_other_keys():
    for k in ("hpcosim/run/r1/ctrl/alive", "hpcosim/run/r1/can/up", "x/run/r1/can/tx"):
        with pytest.raises(ValueError):
            keys.parse_can_key(k)
    with pytest.raises(ValueError, match="node"):
        keys.alive_key("r1", "human")


def test_loopback_classification():
    for ep in ("tcp/127.0.0.1:7447", "udp/127.0.0.5:1", "tcp/[::1]:7447",
               "tcp/localhost:7447", "unixsock-stream//tmp/z.sock",
               "tcp/127.0.0.1:7447#iface=lo", "tls/127.0.0.1:9?prio=1"):
        assert is_loopback_endpoint(ep), ep
    for ep in ("tcp/0.0.0.0:7447", "tcp/[::]:0", "tcp/192.168.1.10:7447",
               "tcp/example.org:7447"):
        assert not is_loopback_endpoint(ep), ep
    for bad in ("tcp127.0.0.1:7", "tcp/127.0.0.1", "tcp/127.0.0.1:x"):
        with pytest.raises(ValueError, match="endpoint"):
            is_loopback_endpoint(bad)


def test_config_is_loopback_only_by_default():
    ep = loopback_endpoint(7449)
    assert ep == "tcp/127.0.0.1:7449"
    cfg = make_config(listen=[ep], connect="tcp/127.0.0.1:7450, tcp/[::1]:7451")
    assert json.loads(cfg.get_json("mode")) == "peer"
    assert json.loads(cfg.get_json("scouting/multicast/enabled")) is False
    assert json.loads(cfg.get_json("scouting/gossip/enabled")) is False
    assert json.loads(cfg.get_json("listen/endpoints")) == [ep]
    assert json.loads(cfg.get_json("connect/endpoints")) == ["tcp/127.0.0.1:7450",
                                                             "tcp/[::1]:7451"]
    # no endpoints: listens nowhere (zenoh's default would be tcp/[::]:0)
    assert json.loads(make_config().get_json("listen/endpoints")) == []


def test_remote_endpoints_and_options_need_explicit_permission():
    with pytest.raises(ValueError, match="not loopback"):
        make_config(listen=["tcp/0.0.0.0:7447"])
    with pytest.raises(ValueError, match="allow_remote"):
        make_config(options={"scouting/multicast/enabled": True})
    cfg = make_config(connect=["tcp/10.0.0.2:7447"], allow_remote=True)
    assert json.loads(cfg.get_json("connect/endpoints")) == ["tcp/10.0.0.2:7447"]
    cfg = make_config(options={"transport/unicast/lowlatency": False})
    assert json.loads(cfg.get_json("transport/unicast/lowlatency")) is False
    cfg = make_config(low_latency=True)
    assert json.loads(cfg.get_json("transport/unicast/lowlatency")) is True
    assert json.loads(cfg.get_json("transport/unicast/qos/enabled")) is False
    cfg = make_config(low_latency=True, options={"transport/unicast/lowlatency": False})
    assert json.loads(cfg.get_json("transport/unicast/lowlatency")) is False  # options last
    with pytest.raises(ValueError, match="client"):
        make_config(mode="client")
    with pytest.raises(ValueError, match=r"^zenoh mode 'router': expected one of peer, client$"):
        make_config(mode="router")
    for m in ("peer", ZenohMode.PEER):  # the word zenoh reads, either way
        assert json.loads(make_config(mode=m).get_json("mode")) == "peer"


def test_two_loopback_sessions_exchange_a_sample():
    ep = loopback_endpoint(free_tcp_port())
    a = zenoh.open(make_config(listen=[ep]))
    b = zenoh.open(make_config(connect=[ep]))
    try:
        sub = a.declare_subscriber("hpcosim/test/k", zenoh.handlers.FifoChannel(16))
        pub = b.declare_publisher("hpcosim/test/k")
        deadline = time.monotonic() + 5
        while not publisher_matched(pub) and time.monotonic() < deadline:
            time.sleep(0.005)
        pub.put(b"\x01\x02")
        got = None
        while got is None and time.monotonic() < deadline:
            got = sub.try_recv()
            time.sleep(0.001)
        assert got is not None and got.payload.to_bytes() == b"\x01\x02"
        links = [str(x) for x in b.info.peers_zid()]
        assert links == [str(a.zid())]
    finally:
        b.close()
        a.close()
