"""Benchmark: what a pause between ticks does to the cost of the same tick on this machine.

In the lockstep co-simulation each process waits about 100-400 us between its bursts of
work while the other side computes; in microbenchmarks (``bench_controllers.py``,
``bench_fmu.py``) the same code runs back to back.  This script runs the same controller
ticks (the relaxed interaction-aware CLF-QP ``clfqp`` and ``pd``, 1 kHz measurements along
the gait's prosthesis stance, as in ``bench_controllers.py``), one controller per way of
running, all along the same measurements, taking turns every ``--block`` ticks:

  - ``back-to-back``: one tick right after the other (the microbenchmarks' way);
  - ``after a sleep``: each tick after ``time.sleep(gap)`` (the thread blocks; the CPU may
    idle or run something else);
  - ``after a yield-poll``: each tick after ``gap`` of ``os.sched_yield()`` polling (what a
    receiving side does while it waits: ``bus_schemas.transport.receiver.Receiver``);
  - ``after a busy spin``: each tick after ``gap`` of a Python loop reading the clock (no
    system call: the thread keeps the CPU).

Each tick is timed with the thread's CPU clock (``time.thread_time_ns``) and the wall
clock: CPU time equal to wall time means the tick itself ran slower, not that it was
preempted.  Prints medians and the ratios to back-to-back of the same round (the machine
is shared and its speed drifts: quote the ratios).

Usage: PYTHONPATH=. python benchmarks/bench_cold_tick.py [--gait G --tube T]
       [--ticks 2000] [--rounds 3] [--gap-us 300] [--json out.json]
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # tests.* helpers

import hp_model
from hp_model.atomic_io import atomic_write_text
from hp_model.force_tube import load_tube
from hp_model.gait_artifact import load_gait
from prosthesis_controller import ControllerContext, make_controller
from tests.controller_support import stance_ticks

ROOT = Path(__file__).resolve().parents[1]
GAIT = ROOT / "tests/data/controller/gait_demo.json"
TUBE = ROOT / "tests/data/controller/tube_demo.json"
MODES = ("back-to-back", "after a sleep", "after a yield-poll", "after a busy spin")


def pause(mode: str, gap_ns: int) -> None:
    """``mode``'s pause of ``gap_ns`` before a tick."""
    pc = time.perf_counter_ns
    if mode == MODES[1]:
        time.sleep(gap_ns * 1e-9)
    elif mode == MODES[2]:
        end = pc() + gap_ns
        while pc() < end:
            os.sched_yield()
    elif mode == MODES[3]:
        end = pc() + gap_ns
        while pc() < end:
            pass


def run(make, meas, u0, gap_s: float, block: int) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """(CPU us, wall us) of each tick of ``meas`` per mode: one controller per mode, all
    along the same measurements, the modes taking turns every ``block`` ticks (so a drift
    of the machine's speed meets every mode alike)."""
    ctls = {m: make() for m in MODES}
    for c in ctls.values():
        c.reset(u0)
    n = len(meas)
    cpu = {m: np.empty(n) for m in MODES}
    wall = {m: np.empty(n) for m in MODES}
    tc, pc = time.thread_time_ns, time.perf_counter_ns
    gap_ns = int(gap_s * 1e9)
    for b in range(0, n, block):
        for m, ctl in ctls.items():
            tick, c_m, w_m = ctl.tick, cpu[m], wall[m]
            for k in range(b, min(n, b + block)):
                pause(m, gap_ns)
                w0 = pc()  # the CPU-time interval nested inside the wall-time one
                c0 = tc()
                tick(meas[k])
                c1 = tc()
                w_m[k], c_m[k] = pc() - w0, c1 - c0
    return {m: (cpu[m] / 1e3, wall[m] / 1e3) for m in MODES}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--gait", type=Path, default=GAIT)
    ap.add_argument("--tube", type=Path, default=TUBE)
    ap.add_argument("--ticks", type=int, default=2000)
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--gap-us", type=float, default=300.0)
    ap.add_argument("--block", type=int, default=50, help="ticks per turn of a mode")
    ap.add_argument("--json", help="also write the figures to this JSON file")
    a = ap.parse_args()
    if a.ticks < 10 or a.rounds < 1 or a.gap_us <= 0 or a.block < 1:
        ap.error("--ticks >= 10, --rounds >= 1, --gap-us > 0 and --block >= 1")

    model = hp_model.load_model()
    gait = load_gait(a.gait, model.parameter_hash())
    tube = load_tube(a.tube, gait.hash())
    ctx = ControllerContext(gait, tube, model)
    meas, u0 = stance_ticks(model, gait, a.ticks)
    names = ("clfqp", "pd")
    makers = {n: (lambda n=n: make_controller(n, gait, tube, model, context=ctx))
              for n in names}
    for mk in makers.values():  # warm-up
        run(mk, meas[:200], u0, a.gap_us * 1e-6, a.block)

    # per controller and mode: the rounds' medians (CPU, wall)
    med: dict[str, dict[str, list[tuple[float, float]]]] = {
        n: {m: [] for m in MODES} for n in names}
    for r in range(a.rounds):
        for n, mk in makers.items():
            for m, (cpu, wall) in run(mk, meas, u0, a.gap_us * 1e-6, a.block).items():
                med[n][m].append((float(np.median(cpu)), float(np.median(wall))))
        print(f"round {r + 1}/{a.rounds} done", file=sys.stderr)

    print(f"\n{a.ticks} stance ticks per round x {a.rounds} rounds, pause {a.gap_us:g} us; "
          f"median per tick (us), CPU / wall; ratio: CPU median to back-to-back's, same "
          f"round (median and range over the rounds)\n")
    print("| controller | " + " | ".join(MODES) + " | "
          + " | ".join(f"ratio {m}" for m in MODES[1:]) + " |")
    print("|---|" + "---:|" * (2 * len(MODES) - 1))
    out: dict = {"ticks": a.ticks, "rounds": a.rounds, "gap_us": a.gap_us, "controllers": {}}
    for n in names:
        cells = []
        for m in MODES:
            cpu = float(np.median([x[0] for x in med[n][m]]))
            wall = float(np.median([x[1] for x in med[n][m]]))
            cells.append(f"{cpu:.1f} / {wall:.1f}")
        ratios = {}
        for m in MODES[1:]:
            rr = [x[0] / b[0] for x, b in zip(med[n][m], med[n][MODES[0]], strict=True)]
            ratios[m] = rr
            cells.append(f"{np.median(rr):.2f} [{min(rr):.2f} .. {max(rr):.2f}]")
        print(f"| {n} | " + " | ".join(cells) + " |")
        out["controllers"][n] = {"medians_cpu_wall_us": med[n], "ratios": ratios}
    if a.json:
        atomic_write_text(a.json, json.dumps(out, indent=2))


if __name__ == "__main__":
    main()
