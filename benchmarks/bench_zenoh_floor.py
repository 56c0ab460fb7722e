"""The floor of the co-simulation's exchange: a bare zenoh ping-pong between two processes
with the co-simulation's session config (loopback TCP, low-latency transport, each process
pinned on its own CPU, the receiver polling ``try_recv`` with ``sched_yield`` before it
would block), payloads of the co-simulation's size (a 5-frame batch out, a 1-frame reply).

No CAN encoding, no checks, no controller: what a lockstep tick can never go below, apart
from the FMU step and the controller tick.  ``--work-us W`` makes the echo side spin W us
before it answers (a stand-in for the controller tick, to see whether the transport's cost
changes when the echo side is busy). ``--shm``: zenoh's shared-memory transport enabled on
both sessions and every payload put from a buffer of a shared-memory provider (zenoh would
otherwise send payloads under its 3 KiB threshold over the link as usual); the sample's
notification still travels over the link. ``--unix``: a unix-socket endpoint instead of
TCP on the loopback.

    PYTHONPATH=. python benchmarks/bench_zenoh_floor.py [--n 5000] [--work-us 0] \
        [--no-low-latency] [--no-pin] [--shm] [--unix] [--json out.json]
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

import zenoh
import zenoh.shm

from bus_schemas.transport.zenoh_config import loopback_endpoint, make_config

OUT, BACK = 122, 26  # bytes: the plant's 5-frame batch, the controller's 1-frame reply
KEY_OUT, KEY_BACK = "floor/out", "floor/back"


def _pin(cpu: int | None) -> None:
    if cpu is not None and len(os.sched_getaffinity(0)) >= 2:
        os.sched_setaffinity(0, {sorted(os.sched_getaffinity(0))[cpu]})


def _wait(handler: zenoh.Handler, poll_s: float) -> zenoh.Sample:
    """The next sample: poll (yielding) up to ``poll_s``, then block."""
    end = time.perf_counter() + poll_s
    while time.perf_counter() < end:
        s = handler.try_recv()
        if s is not None:
            return s
        os.sched_yield()
    return handler.recv()


def _session(a: argparse.Namespace, **ends: str) -> zenoh.Session:
    opts = {"transport/shared_memory/enabled": True} if a.shm else {}
    return zenoh.open(make_config(low_latency=not a.no_low_latency, options=opts, **ends))


def _sender(a: argparse.Namespace, pub: zenoh.Publisher, data: bytes) -> Callable[[], None]:
    """A function putting ``data`` (from a shared-memory buffer each time with ``--shm``)."""
    if not a.shm:
        return lambda: pub.put(data)
    provider = zenoh.shm.ShmProvider.default_backend(1 << 20)
    n, policy = len(data), zenoh.shm.BlockOn()

    def put() -> None:
        buf = provider.alloc(n, policy=policy)
        buf[0:n] = data
        pub.put(buf)
    return put


def _publisher(s: zenoh.Session, key: str) -> zenoh.Publisher:
    return s.declare_publisher(key, congestion_control=zenoh.CongestionControl.BLOCK,
                               priority=zenoh.Priority.REAL_TIME, express=True,
                               reliability=zenoh.Reliability.RELIABLE)


def echo(a: argparse.Namespace) -> None:
    """The echo process: answer each sample with a BACK-byte one until an empty one."""
    _pin(None if a.no_pin else 1)
    s = _session(a, connect=a.echo)
    sub = s.declare_subscriber(KEY_OUT, zenoh.handlers.RingChannel(1024))
    pub = _publisher(s, KEY_BACK)
    print("ready", flush=True)
    reply = _sender(a, pub, bytes(BACK))
    spin = a.work_us * 1e-6
    while True:
        smp = _wait(sub.handler, a.poll_us * 1e-6)
        data = smp.payload.to_bytes()
        if not data:
            break
        if spin:
            end = time.perf_counter() + spin
            while time.perf_counter() < end:
                pass
        reply()
    s.close()


def ping(a: argparse.Namespace) -> dict[str, float]:
    _pin(None if a.no_pin else 0)
    ep = (f"unixsock-stream/{tempfile.gettempdir()}/zenoh-floor-{os.getpid()}.sock"
          if a.unix else loopback_endpoint())
    s = _session(a, listen=ep)
    sub = s.declare_subscriber(KEY_BACK, zenoh.handlers.RingChannel(1024))
    pub = _publisher(s, KEY_OUT)
    proc = subprocess.Popen([sys.executable, __file__, "--echo", ep, "--poll-us",
                             str(a.poll_us), "--work-us", str(a.work_us)]
                            + (["--no-low-latency"] if a.no_low_latency else [])
                            + (["--no-pin"] if a.no_pin else [])
                            + (["--shm"] if a.shm else []) + (["--unix"] if a.unix else []),
                            stdout=subprocess.PIPE, text=True)
    try:
        assert proc.stdout is not None and proc.stdout.readline().strip() == "ready"
        while not getattr(pub.matching_status, "matching", False):
            time.sleep(0.01)
        out, rtt = _sender(a, pub, bytes(OUT)), []
        for _ in range(a.n):
            t0 = time.perf_counter_ns()
            out()
            _wait(sub.handler, a.poll_us * 1e-6)
            rtt.append(time.perf_counter_ns() - t0)
        pub.put(b"")
        proc.wait(10)
    finally:
        if proc.poll() is None:
            proc.kill()
        s.close()
    r = sorted(x * 1e-3 for x in rtt[200:])
    return {"median_us": statistics.median(r), "mean_us": statistics.fmean(r),
            "p99_us": r[int(0.99 * len(r))], "n": len(r), "load": os.getloadavg()[0]}


def main() -> None:
    p = argparse.ArgumentParser()
    p.add_argument("--n", type=int, default=5000)
    p.add_argument("--work-us", type=float, default=0.0)
    p.add_argument("--poll-us", type=float, default=300.0)
    p.add_argument("--no-low-latency", action="store_true")
    p.add_argument("--no-pin", action="store_true")
    p.add_argument("--shm", action="store_true")
    p.add_argument("--unix", action="store_true")
    p.add_argument("--json", type=Path)
    p.add_argument("--echo", help=argparse.SUPPRESS)
    a = p.parse_args()
    if a.echo:
        echo(a)
        return
    fig = ping(a)
    print(", ".join(f"{k} {v:.1f}" for k, v in fig.items()))
    if a.json:
        a.json.write_text(json.dumps(fig, indent=2))


if __name__ == "__main__":
    main()
