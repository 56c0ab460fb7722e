"""Issue 39: ``hpcosim controller serve`` over zenoh authenticates its plant with a key file,
as ``hpcosim run`` does with its run secret: a local user without the key (or with another
key) who joins the node's endpoint as a plant gets no torque command, the plant with the key
is served.  And the key file itself: one line, a secret of 16 characters or more, in a file
nobody else may read or change."""

from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path

import pytest

from bus_schemas.transport import codec
from bus_schemas.transport.bus_config import (
    BusConfigError,
    bus_config_from_dict,
    make_bus,
    read_key,
)
from bus_schemas.transport.protocol import FrameId
from bus_schemas.transport.zenoh_can import ZenohBus
from bus_schemas.transport.zenoh_config import loopback_endpoint
from prosthesis_controller.node import SUMMARY_PREFIX

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT / "tests" / "data" / "controller"
SECRET = "3FqUe0b9Lw-YxTz7c1Rk5mNp2sVd8Ha4"


def _key(path: Path, secret: str = SECRET, mode: int = 0o600) -> Path:
    path.write_text(secret + "\n")
    path.chmod(mode)
    return path


def _drive(bus, seconds: float) -> tuple[int, int]:
    """Play the plant on ``bus`` for ``seconds``: a full cycle of feedback frames every
    20 ms; (cycles sent, enabled TorqueCmd frames received)."""
    sent = torques = 0
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        for m in codec.encode_feedback(0.1, 0.0, 0.2, 0.0, 500.0, True, sent % 16,
                                       sim_time_us=sent * 1000):
            bus.send(m)
        sent += 1
        until = time.monotonic() + 0.02
        while (left := until - time.monotonic()) > 0:
            m = bus.recv(left)
            if m is not None and m.arbitration_id == FrameId.TORQUE_CMD:
                torques += codec.decode(m).value.enable
    return sent, torques


@pytest.fixture
def served(tmp_path):
    """``hpcosim controller serve`` of pd over zenoh with a key file, listening on a
    loopback endpoint; (endpoint, run id, key file, process)."""
    key = _key(tmp_path / "lab.key")
    endpoint, run_id = loopback_endpoint(), f"keyed-{os.getpid()}"
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    proc = subprocess.Popen(
        [sys.executable, "-m", "orchestrator.cli", "controller", "serve", "--controller", "pd",
         "--gait", str(DATA / "gait_demo.json"), "--tube", str(DATA / "tube_demo.json"),
         "--run-id", run_id, "--listen", endpoint, "--key", str(key)],
        env=env, cwd=str(tmp_path), stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        assert proc.stdout is not None and proc.stdout.readline().strip() == "ready"
        yield endpoint, run_id, key, proc
    finally:
        if proc.poll() is None:
            proc.terminate()
        proc.wait(30)


def test_only_the_plant_with_the_key_gets_torque_commands(served, tmp_path):
    endpoint, run_id, _, proc = served
    # a local user who knows the run id and the endpoint, without a key
    intruder = ZenohBus(f"{run_id}/plant", connect=endpoint)
    try:
        sent, torques = _drive(intruder, 1.5)
    finally:
        intruder.shutdown()
    assert sent > 30 and torques == 0
    # with a key of its own
    other = _key(tmp_path / "other.key", "Zz" * 16)
    bus = make_bus(bus_config_from_dict({"run_id": run_id, "connect": [endpoint],
                                         "key_file": str(other)}), "plant")
    try:
        sent, torques = _drive(bus, 1.5)
    finally:
        bus.shutdown()
    assert sent > 30 and torques == 0
    # the lab's plant: its bus config names the same key file (read by make_bus, at a
    # moment when the node's own copy of the dictionary is long closed)
    cfg = tmp_path / "plant.toml"
    cfg.write_text(f'run_id = "{run_id}"\nconnect = ["{endpoint}"]\nkey_file = "lab.key"\n')
    from bus_schemas.transport.bus_config import load_bus_config

    bus = make_bus(load_bus_config(cfg), "plant")
    try:
        sent, torques = _drive(bus, 1.5)
    finally:
        bus.shutdown()
    assert sent > 30 and torques >= sent - 2  # every cycle answered (the last may be late)
    _, err = proc.communicate(timeout=30)  # the node leaves with its plant
    assert proc.returncode == 0, err
    said = " ".join(err.split())  # the node's summary, as the verb prints it
    assert SUMMARY_PREFIX in said and "'reason': 'plant gone'" in said, err
    assert f"'ticks': {torques}," in said, err


def test_a_key_file_is_one_private_line(tmp_path):
    ok = _key(tmp_path / "ok.key")
    assert read_key(ok) == SECRET
    link = tmp_path / "link.key"
    link.symlink_to(ok)
    assert read_key(link) == SECRET  # the file opened is checked, whatever its name
    for mode in (0o644, 0o640, 0o604, 0o660, 0o606):
        with pytest.raises(BusConfigError, match=f"mode {mode:04o}.*chmod 600"):
            read_key(_key(tmp_path / f"m{mode:o}.key", mode=mode))
    assert read_key(_key(tmp_path / "ro.key", mode=0o400)) == SECRET
    for text, words in (("", "one line"), (f"{SECRET}\n{SECRET}", "one line"),
                        ("short", "at least 16"), (f"{SECRET}:x", "':'"),
                        (f"{SECRET} x", "spaces")):
        p = tmp_path / "k.key"
        p.write_text(text)
        p.chmod(0o600)
        with pytest.raises(BusConfigError, match=words):
            read_key(p)
    fifo = tmp_path / "fifo.key"
    os.mkfifo(fifo, 0o600)
    with pytest.raises(BusConfigError, match="not a regular file"):
        read_key(fifo)  # refused without waiting for a writer
    with pytest.raises(BusConfigError, match="No such file"):
        read_key(tmp_path / "none.key")
    big = tmp_path / "big.key"
    big.write_text("x" * 5000)
    big.chmod(0o600)
    with pytest.raises(BusConfigError, match="over 4096 bytes"):
        read_key(big)


@pytest.mark.skipif(os.geteuid() != 0, reason="chown to another user needs root")
def test_a_key_file_of_another_user_is_refused(tmp_path):
    p = _key(tmp_path / "theirs.key")
    os.chown(p, 12345, 12345)
    with pytest.raises(BusConfigError, match="owned by uid 12345"):
        read_key(p)


def test_the_node_takes_one_key(tmp_path):
    """``python -m prosthesis_controller.node``: ``--key`` and ``--auth-stdin`` are two keys
    (one line, exit 2); over zenoh with neither it refuses to serve."""
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    base = [sys.executable, "-m", "prosthesis_controller.node", "--controller", "pd",
            "--gait", str(DATA / "gait_demo.json"), "--tube", str(DATA / "tube_demo.json")]
    key = _key(tmp_path / "lab.key")
    for extra, words in ((["--key", str(key), "--auth-stdin"], "give one key"),
                         ([], "needs a key file")):
        p = subprocess.run([*base, *extra], env=env, cwd=str(ROOT), input="s" * 32 + "\n",
                           capture_output=True, text=True, timeout=120)
        assert p.returncode == 2, p.stderr
        assert p.stderr.strip().count("\n") == 0 and words in p.stderr, p.stderr
