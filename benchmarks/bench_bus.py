"""Benchmark: CAN codec (fast path vs cantools), frame checker, MCAP writes, and the ZenohBus
round trip between two OS processes on TCP loopback.

Per call from Python, best of several repeats (the machines are shared: quote ratios):
  - encode: ``encode_torque`` / ``encode_feedback`` (fast path, a can.Message with counter
    and CRC) against cantools ``Message.encode`` strict / non-strict (bytes only);
  - decode: ``decode`` (checks + typed payload) and ``FrameChecker.check`` against cantools
    ``Message.decode`` (dict only, and with the CRC check added);
  - MCAP: ``Recorder.write`` of a CAN frame record and a ground-truth record (zstd);
  - zenoh: plant ``ZenohBus`` -> echo process (``ctrl`` role) -> back, median and p99.

Usage: PYTHONPATH=. python benchmarks/bench_bus.py [--frames 3000] [--json out.json]
"""

from __future__ import annotations

import argparse
import itertools
import json
import statistics
import subprocess
import sys
import tempfile
import time
import timeit
from pathlib import Path

import can

from bus_schemas.recording.recorder import Recorder
from bus_schemas.transport import codec, protocol
from bus_schemas.transport.crc8 import frame_checksum
from bus_schemas.transport.zenoh_can import ZenohBus
from bus_schemas.transport.zenoh_config import loopback_endpoint
from hp_model.domains import Domain


def per_call_us(fn, number: int = 20_000, repeat: int = 7) -> float:
    return min(timeit.repeat(fn, number=number, repeat=repeat)) / number * 1e6


def codec_figures() -> dict[str, float]:
    db = protocol.database()
    tm = db.get_message_by_frame_id(protocol.FrameId.TORQUE_CMD)
    sig = {"KneeTorqueCmd": 1.234567, "AnkleTorqueCmd": -2.5, "TorqueEnable": 1,
           "Counter": 3, "Checksum": 0}
    msg = codec.encode_torque(1.234567, -2.5, 3)
    data = bytes(msg.data)
    checker = codec.FrameChecker()
    seq = itertools.cycle([codec.encode_torque(1.234567, -2.5, k) for k in range(16)])
    return {
        "encode_torque (fast, Message+CRC)": per_call_us(
            lambda: codec.encode_torque(1.234567, -2.5, 3)),
        "encode_feedback, 4 frames (fast)": per_call_us(
            lambda: codec.encode_feedback(0.5, 1.0, -0.2, 0.3, 700.0, True, 3,
                                          sim_time_us=1000), number=5000),
        "cantools encode strict (bytes)": per_call_us(lambda: tm.encode(sig, strict=True)),
        "cantools encode non-strict (bytes)": per_call_us(
            lambda: tm.encode(sig, strict=False)),
        "encode_cantools (clamp+cantools+CRC+Message)": per_call_us(
            lambda: codec.encode_cantools("TorqueCmd", sig, 3), number=5000),
        "decode (fast, checks + typed)": per_call_us(lambda: codec.decode(msg)),
        "FrameChecker.check (counter advancing)": per_call_us(
            lambda: checker.check(next(seq))),
        "cantools decode (dict)": per_call_us(
            lambda: tm.decode(data, decode_choices=False, allow_excess=False)),
        "cantools decode + CRC check (dict)": per_call_us(
            lambda: frame_checksum(0x010, data) == data[7]
            and tm.decode(data, decode_choices=False, allow_excess=False)),
        "quantize_angle (scalar)": per_call_us(lambda: codec.quantize_angle(0.123456789)),
    }


def mcap_figures() -> dict[str, float]:
    frame = codec.encode_torque(1.0, 2.0, 3)
    gt = {"t": 0.1, "socket_force": {"Fx": 1.0, "Fz": -700.0, "My": 0.5},
          "q": [0.1] * 12, "qd": [0.2] * 12, "domain": Domain.PS, "tau": 0.3, "step": 1,
          "fallen": False}
    with tempfile.TemporaryDirectory() as d, Recorder(Path(d) / "b.mcap") as rec:
        rec.register_all()
        can_us = per_call_us(lambda: rec.write_can(frame, "rx", 1), number=5000)
        gt_us = per_call_us(lambda: rec.write("/ground_truth", gt, 1), number=5000)
    return {"MCAP write CAN frame (JSON, zstd)": can_us,
            "MCAP write ground truth (JSON, zstd)": gt_us}


def echo(run_id: str, endpoint: str) -> None:
    """The echo side (a separate process): send every frame back until id 0x7FF."""
    with ZenohBus(f"{run_id}/ctrl", connect=endpoint) as bus:
        print("ready" if bus.wait_for_peer(10.0) else "no-peer", flush=True)
        while (m := bus.recv(10.0)) is not None and m.arbitration_id != 0x7FF:
            bus.send(m)


def zenoh_figures(frames: int) -> dict[str, float]:
    ep = loopback_endpoint()
    with ZenohBus("bench/plant", listen=ep) as bus:
        proc = subprocess.Popen([sys.executable, __file__, "--echo", "bench", ep],
                                stdout=subprocess.PIPE, text=True)
        try:
            assert proc.stdout is not None and proc.stdout.readline().strip() == "ready"
            bus.wait_for_peer(10.0)
            rtt = []
            for k in range(frames):
                m = codec.encode_torque(0.001 * k, 0.0, k)
                t0 = time.perf_counter()
                bus.send(m)
                if bus.recv(5.0) is None:
                    raise RuntimeError("echo lost a frame")
                rtt.append(time.perf_counter() - t0)
            bus.send(can.Message(arbitration_id=0x7FF, is_extended_id=False))
            proc.wait(10)
        finally:
            if proc.poll() is None:
                proc.kill()
    rtt = sorted(rtt[100:])
    return {"ZenohBus round trip, 2 processes, median": statistics.median(rtt) * 1e6,
            "ZenohBus round trip, 2 processes, p99": rtt[int(0.99 * len(rtt))] * 1e6}


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--frames", type=int, default=3000)
    ap.add_argument("--json", type=Path)
    ap.add_argument("--echo", nargs=2, metavar=("RUN_ID", "ENDPOINT"), help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.echo:
        echo(*args.echo)
        return
    figures = {**codec_figures(), **mcap_figures(), **zenoh_figures(args.frames)}
    width = max(map(len, figures))
    for k, v in figures.items():
        print(f"{k:<{width}}  {v:8.2f} us")
    if args.json:
        args.json.write_text(json.dumps(figures, indent=2))


if __name__ == "__main__":
    main()
