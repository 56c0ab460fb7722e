"""Zenoh key expressions and the loopback-only session configuration."""

from __future__ import annotations

import json
import re
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


# --------------------------------------------------------------------------- bus config types

#: (field, bad value, words of the one-line error): every field of a bus config, a value of the
#: wrong type (or out of its range) for each; the message names the file and the field
BAD_FIELDS = [
    ("interface", 5, "expected a string, not an integer"),
    ("interface", True, "expected a string, not a boolean"),
    ("interface", "", "expected a non-empty string"),
    ("interface", "no-such-can", "unknown; expected one of"),
    ("run_id", 5, "expected a string, not an integer"),
    ("run_id", ["a"], "expected a string, not a list"),
    ("run_id", "a/b", "use 1-128 characters"),
    ("run_id", "run*", "use 1-128 characters"),
    ("channel", 5, "expected a string, not an integer"),
    ("channel", "can0", "not for the zenoh interface"),
    ("listen", 5, "expected a list of endpoint strings, not an integer"),
    ("listen", [1, 2], "expected a list of endpoint strings, not a list"),
    ("listen", {"a": 1}, "expected a list of endpoint strings, not a table"),
    ("listen", ["tcp/0.0.0.0:7447"], "not a loopback endpoint"),
    ("listen", ["nonsense"], "expected <protocol>/<address>"),
    ("connect", True, "expected a list of endpoint strings, not a boolean"),
    ("connect", "tcp/192.168.1.10:7447", "not a loopback endpoint"),
    ("connect", ["tcp/127.0.0.1:70000"], "port 0-65535"),
    ("allow_remote", "false", "expected true or false, not a string"),
    ("allow_remote", "true", "expected true or false, not a string"),
    ("allow_remote", 0, "expected true or false, not an integer"),
    ("allow_remote", 1.0, "expected true or false, not a number"),
    ("key_file", 5, "expected a string, not an integer"),
    ("key_file", ["k"], "expected a string, not a list"),
    ("options", "low_latency", "expected a table (keys: strings), not a string"),
    ("options", [1], "expected a table (keys: strings), not a list"),
    ("options.bogus", 1, "not an option of the zenoh interface"),
    ("options.poll_us", -1, "expected a finite number >= 0"),
    ("options.poll_us", "fast", "expected a finite number >= 0, not a string"),
    ("options.poll_us", float("inf"), "expected a finite number >= 0"),
    ("options.poll_us", True, "expected a finite number >= 0, not a boolean"),
    ("options.low_latency", "yes", "expected true or false, not a string"),
    ("options.stamp", 1, "expected true or false, not an integer"),
    ("options.receive_own_messages", "no", "expected true or false, not a string"),
    ("options.rx_queue_size", 0, "expected a whole number >= 1"),
    ("options.rx_queue_size", 2.5, "expected a whole number >= 1, not a number"),
    ("options.mode", 1, "expected a string, not an integer"),
    ("options.mode", "router", "expected one of peer, client"),
    ("options.zenoh_options", "x", "expected a table (keys: strings), not a string"),
]


def _table(field: str, value):
    """A bus config's table with ``field`` (``options.KEY`` inside ``options``) = value."""
    if field.startswith("options."):
        return {"options": {field.split(".", 1)[1]: value}}
    return {field: value}


@pytest.mark.parametrize(("field", "value", "words"), BAD_FIELDS,
                         ids=[f"{f}={v!r}" for f, v, _ in BAD_FIELDS])
def test_every_bus_config_field_is_strictly_typed(tmp_path, field, value, words):
    from bus_schemas.transport.bus_config import (
        BusConfigError,
        bus_config_from_dict,
        load_bus_config,
    )

    with pytest.raises(BusConfigError) as e:
        bus_config_from_dict(_table(field, value), "bus.toml")
    msg = str(e.value)
    assert "\n" not in msg and msg.startswith(f"bus.toml: {field}"), msg
    assert words in msg, msg
    # the same from a JSON file: the message names the file and the field
    p = tmp_path / "bus.json"
    p.write_text(json.dumps(_table(field, value)))
    with pytest.raises(BusConfigError, match=f"^{p}: {field}"):
        load_bus_config(p)


def test_a_string_is_not_a_boolean_in_a_toml_bus_file(tmp_path):
    """The issue's case: ``allow_remote = "false"`` was taken as true, and a 0.0.0.0 listen
    endpoint followed; now the file is refused in one line naming the field."""
    from bus_schemas.transport.bus_config import BusConfigError, load_bus_config

    p = tmp_path / "bus.toml"
    p.write_text('allow_remote = "false"\nlisten = ["tcp/0.0.0.0:7447"]\n')
    with pytest.raises(BusConfigError, match=r"allow_remote = 'false': expected true or false"):
        load_bus_config(p)
    p.write_text('allow_remote = false\nlisten = ["tcp/0.0.0.0:7447"]\n')
    with pytest.raises(BusConfigError, match=r"listen endpoint 'tcp/0.0.0.0:7447': not a "
                       r"loopback endpoint"):
        load_bus_config(p)
    p.write_text('allow_remote = true\nlisten = ["tcp/0.0.0.0:7447"]\n')
    assert load_bus_config(p).listen == ("tcp/0.0.0.0:7447",)  # said explicitly: allowed


def test_valid_bus_configs_load_with_their_types(tmp_path):
    from bus_schemas.transport.bus_config import bus_config_from_dict, load_bus_config

    c = bus_config_from_dict({"run_id": "r1", "listen": "tcp/127.0.0.1:1, tcp/[::1]:2",
                              "connect": ["unixsock-stream//tmp/z.sock"],
                              "options": {"low_latency": True, "poll_us": 300,
                                          "rx_queue_size": 64, "mode": "peer",
                                          "zenoh_options": {"a/b": 1}}})
    assert c.listen == ("tcp/127.0.0.1:1", "tcp/[::1]:2") and c.allow_remote is False
    assert bus_config_from_dict({"interface": "virtual", "channel": "c"}).channel == "c"
    assert bus_config_from_dict({"interface": "socketcan", "channel": "can0",
                                 "options": {"bitrate": 500000}}).options == {"bitrate": 500000}
    (tmp_path / "b.json").write_text('{"channel": null, "key_file": "k.key"}')
    assert load_bus_config(tmp_path / "b.json").key_file == str(tmp_path / "k.key")


@pytest.mark.parametrize(("table", "words"), [
    ({"interface": "virtual", "listen": ["tcp/127.0.0.1:1"]}, "listen = "),
    ({"interface": "virtual", "key_file": "k"}, "key_file = 'k': only for the zenoh"),
    ({"interface": "virtual", "allow_remote": True}, "allow_remote = True: not for"),
    ({"interface": "udp_multicast"}, "reaches other machines over IP"),
    ({"interface": "socketcan", "options": {"channel": "x"}}, "fields of the bus config"),
    ({"options": {"zenoh_options": {"connect/endpoints": ["tcp/1.2.3.4:1"]}}},
     "options.zenoh_options.connect/endpoints"),
], ids=["endpoints on virtual", "key on virtual", "allow_remote on virtual", "udp_multicast",
        "a field as an option", "guarded zenoh option"])
def test_a_field_the_interface_has_no_use_for_is_refused(table, words):
    from bus_schemas.transport.bus_config import BusConfigError, bus_config_from_dict

    with pytest.raises(BusConfigError, match=re.escape(words)):
        bus_config_from_dict(table, "bus.toml")


def test_command_line_overrides_are_named_as_options(tmp_path):
    """An override given on the command line is named by its option, a field of the file by
    the file and the field."""
    from bus_schemas.transport.bus_config import BusConfigError
    from prosthesis_controller.node import bus_config_from_args

    with pytest.raises(BusConfigError, match=r"^--listen 'tcp/0.0.0.0:1': not a loopback"):
        bus_config_from_args(None, listen="tcp/0.0.0.0:1")
    with pytest.raises(BusConfigError, match=r"^--run-id 'a/b': use 1-128"):
        bus_config_from_args(None, run_id="a/b")
    p = tmp_path / "bus.toml"
    p.write_text('allow_remote = true\n')
    cfg = bus_config_from_args(str(p), listen="tcp/0.0.0.0:1")  # the file allows it
    assert cfg.listen == ("tcp/0.0.0.0:1",) and cfg.allow_remote


def test_make_bus_checks_a_config_built_in_code():
    from bus_schemas.transport.bus_config import BusConfig, BusConfigError, make_bus

    with pytest.raises(BusConfigError, match="allow_remote = 'false'"):
        make_bus(BusConfig(allow_remote="false"), "plant")  # type: ignore[arg-type]
    with pytest.raises(BusConfigError, match="listen endpoint"):
        make_bus(BusConfig(listen=("tcp/0.0.0.0:7447",)), "plant")
