"""The ceiling of the lockstep co-simulation's speed on this machine: the real human FMU and
the real prosthesis controller in a closed loop, in two processes pinned like the
co-simulation's, exchanging over zenoh with the co-simulation's session settings, and
nothing else: no CAN frames, counters, checksums or checks, no watchdog, no fault plan, no
recording.  Each 1 ms period the plant puts the prosthesis measurement as 8 packed values
(t, knee and ankle angle and velocity, foot load, contact, socket pitch: what the CAN
frames carry, unquantized), the controller process ticks the controller on it and puts
back the two motor torques, the plant sets them, steps the FMU and reads the next
measurement.  Whatever implementation of the protocol and recording is added to this
loop, the co-simulation cannot run faster than this on the same machine at the same time.

Per run: the real-time factor (simulated time / wall time of the loop), the mean period,
the FMU's share (observe + actuate + doStep, the plant's own clock), the round trip (put ->
torques in hand) and, from the controller process, its mean controller tick.  The walk's
steps are counted from the FMU; a fall ends the run and is reported.

    PYTHONPATH=. python benchmarks/bench_lockstep_floor.py [--gait G --tube T]
        [--controller clfqp] [--steps 10] [--runs 3] [--fmu human.fmu] [--poll-us 300]
        [--no-pin] [--json out.json]
"""

from __future__ import annotations

import argparse
import contextlib
import os
import struct
import subprocess
import sys
import threading
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import zenoh  # noqa: E402
from bench_cosim import check_inputs, summarize, write_json  # noqa: E402  (this folder)
from bench_zenoh_floor import _pin, _publisher, _wait  # noqa: E402

from bus_schemas.transport.zenoh_config import loopback_endpoint, make_config  # noqa: E402

MEAS = struct.Struct("<6d?d")  # t, qk, qa, vk, va, load, contact, pitch
TORQUE = struct.Struct("<2d")
TIMES = struct.Struct("<dQ")  # the controller's mean tick (us) and its tick count
KEY_OUT, KEY_BACK = "floor/meas", "floor/torque"
GAIT = ROOT / "tests/data/controller/gait_demo.json"
TUBE = ROOT / "tests/data/controller/tube_demo.json"


def controller_process(a: argparse.Namespace) -> None:
    """Tick the controller on each measurement and answer with its torques until an empty
    sample; then answer with the mean tick."""
    from prosthesis_controller import ProsthesisMeasurement
    from prosthesis_controller.node import build_controller

    _pin(None if a.no_pin else 1)
    ctl = build_controller(a.controller, str(a.gait), str(a.tube))
    ctl.reset()
    s = zenoh.open(make_config(low_latency=True, connect=a.serve))
    sub = s.declare_subscriber(KEY_OUT, zenoh.handlers.RingChannel(1024))
    pub = _publisher(s, KEY_BACK)
    print("ready", flush=True)
    unpack, pack = MEAS.unpack, TORQUE.pack
    tick, clock, poll = ctl.tick, time.perf_counter_ns, a.poll_us * 1e-6
    total, n = 0, 0
    while True:
        data = _wait(sub.handler, poll).payload.to_bytes()
        if not data:
            break
        m = ProsthesisMeasurement(*unpack(data))
        t0 = clock()
        u = tick(m).torque
        total += clock() - t0
        n += 1
        pub.put(pack(float(u[0]), float(u[1])))
    pub.put(TIMES.pack(total / max(n, 1) / 1e3, n))
    time.sleep(0.2)
    s.close()


def _await_controller(proc: subprocess.Popen[str], pub: zenoh.Publisher) -> None:
    """Until the controller process is ready and subscribed to the measurements (an exit
    before that is a one-line error)."""
    assert proc.stdout is not None
    if proc.stdout.readline().strip() != "ready":
        raise SystemExit("bench_lockstep_floor: the controller process did not start")
    while not getattr(pub.matching_status, "matching", False):
        if proc.poll() is not None:
            raise SystemExit("bench_lockstep_floor: the controller process exited "
                             f"({proc.returncode}) before it subscribed")
        time.sleep(0.01)


def one_run(a: argparse.Namespace, fmu_path: Path) -> dict[str, float]:
    from human_fmu.instance import HumanFmu
    from orchestrator.loop.plant import FmuPlant

    fmu = HumanFmu(fmu_path)
    fmu.start({}, {})
    plant = FmuPlant(fmu, 1e-3)
    affinity = os.sched_getaffinity(0)
    _pin(None if a.no_pin else 0)
    ep = loopback_endpoint()
    s = zenoh.open(make_config(low_latency=True, listen=ep))
    sub = s.declare_subscriber(KEY_BACK, zenoh.handlers.RingChannel(1024))
    pub = _publisher(s, KEY_OUT)
    cmd = [sys.executable, __file__, "--serve", ep, "--controller", a.controller, "--gait",
           str(a.gait), "--tube", str(a.tube), "--poll-us", str(a.poll_us)]
    proc = subprocess.Popen(cmd + (["--no-pin"] if a.no_pin else []), stdout=subprocess.PIPE,
                            text=True, env={**os.environ, "PYTHONPATH": str(ROOT)})

    def watch() -> None:  # the controller process gone: wake a blocked receive (empty)
        proc.wait()
        with contextlib.suppress(Exception):
            s.put(KEY_BACK, b"", allowed_destination=zenoh.Locality.SESSION_LOCAL)

    def reply() -> bytes:
        data = _wait(sub.handler, poll).payload.to_bytes()
        if not data:
            raise SystemExit(f"bench_lockstep_floor: the controller process exited "
                             f"({proc.returncode}) during the run")
        return data

    poll = a.poll_us * 1e-6
    threading.Thread(target=watch, daemon=True).start()
    try:
        _await_controller(proc, pub)
        pack, unpack = MEAS.pack, TORQUE.unpack
        clock = time.perf_counter_ns
        fmu_ns = rtt_ns = 0
        k = 0
        fell = ""
        t_start = clock()
        while True:
            t0 = clock()
            obs = plant.observe()
            if plant.fall is not None:
                fell = plant.fall.reason.name
                break
            if obs.steps >= a.steps:
                break
            y = obs.sensed
            t1 = clock()
            pub.put(pack(obs.t, y.knee_angle, y.ankle_angle, y.knee_velocity,
                         y.ankle_velocity, y.foot_load, y.contact, y.socket_pitch))
            u = unpack(reply())
            t2 = clock()
            plant.actuate(u)
            plant.advance()
            fmu_ns += (t1 - t0) + (clock() - t2)
            rtt_ns += t2 - t1
            k += 1
        wall_ns = clock() - t_start
        pub.put(b"")
        mean_tick, n = TIMES.unpack(reply())
        proc.wait(10)
    finally:
        if proc.poll() is None:
            proc.kill()
        s.close()
        fmu.free()
        os.sched_setaffinity(0, affinity)
    if fell:
        raise SystemExit(f"bench_lockstep_floor: the walker fell ({fell}) at period {k}")
    if n != k:
        raise SystemExit(f"bench_lockstep_floor: {k} periods but {n} controller ticks")
    return {"real_time_factor": k * 1e6 / wall_ns, "period": wall_ns / k / 1e3,
            "round trip": rtt_ns / k / 1e3, "fmu": fmu_ns / k / 1e3,
            "controller tick (controller process)": mean_tick, "periods": float(k),
            "load": os.getloadavg()[0]}


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--gait", type=Path, default=GAIT)
    p.add_argument("--tube", type=Path, default=TUBE)
    p.add_argument("--fmu", type=Path, help="the human FMU (default: the co-simulation's "
                   "cached build for --gait)")
    p.add_argument("--controller", default="clfqp")
    p.add_argument("--steps", type=int, default=10)
    p.add_argument("--runs", type=int, default=3)
    p.add_argument("--poll-us", type=float, default=300.0)
    p.add_argument("--no-pin", action="store_true")
    p.add_argument("--json", type=Path)
    p.add_argument("--serve", help=argparse.SUPPRESS)
    a = p.parse_args()
    if a.serve:
        controller_process(a)
        return
    check_inputs(p, a)

    import hp_model
    from orchestrator.cosim.human import ensure_fmu

    fmu_path = ensure_fmu(a.gait, hp_model.load_model(), a.fmu, lambda m: print(m))
    runs = []
    for r in range(a.runs):
        f = one_run(a, fmu_path)
        runs.append(f)
        print(f"run {r + 1}: " + ", ".join(f"{k} {v:.2f}" for k, v in f.items()), flush=True)
    summary = summarize(runs, "us per period")
    if a.json:
        write_json(a.json, a, summary)

if __name__ == "__main__":
    main()
