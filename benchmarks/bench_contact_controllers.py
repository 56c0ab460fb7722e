"""Benchmark: per-tick cost of the multi-contact graph's prosthesis controllers, ``clfqp``
(prosthesis_controller/contact_clf_qp.py) and ``contact-pd``
(prosthesis_controller/contact_phase_pd.py), each on the measurements of its own walk.

The committed openOFM multi-contact cycle (tests/data/gaits) is walked in the in-process
plant with the prosthesis on the controller (stance and swing); every measurement the
controller read is kept, then replayed through the reset controller ``--repeats`` times,
each tick timed.  Issue 37's target: the controller tick <= 40 us median.  The machine is
shared and noisy: the spread over the repeats is printed with the median.

With ``--cycle GAIT.json`` the cycle of a multi-contact gait file instead (``gait fit``'s:
its model carries the drives' armature, which the committed cycle predates).  With
``--library LIB.json`` (``hpcosim gait library``) the two controllers following the
person's speed over it (:func:`orchestrator.cosim.following.speed_following`),
the person walking the library at ``--speed`` (issue 38's target: the same 40 us).

Usage: python benchmarks/bench_contact_controllers.py [--cycle GAIT.json]
       [--library LIB.json [--speed 0.9]] [--swing-phase time|thigh] [--steps 6]
       [--repeats 5] [--json out.json]
"""

from __future__ import annotations

import argparse
import gc
import json
import platform
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # tests.* helpers

from characterization.gait.contact_gait import GAINS, contact_gait_of, start_state
from characterization.gait.multicontact import GRAPH
from hp_model.leg_kinematics import LegKinematics
from orchestrator.cosim.contact_controllers import (
    contact_clfqp,
    controller_tables,
    loop_simulator,
)
from orchestrator.loop.link import measurement
from orchestrator.loop.plant import SimulatorPlant
from prosthesis_controller.contact_phase_pd import (
    DEFAULT_SWING_PHASE,
    SWING_PHASES,
    ContactPhasePD,
)
from prosthesis_controller.interface import Controller
from prosthesis_controller.measurement import ProsthesisMeasurement
from tests.multicontact_cycle import load_cycle


def cycle(path: Path | None) -> tuple[Any, Any, Any]:
    """(model, trajectories, durations) of a gait file's cycle, else of the committed one."""
    if path is None:
        model, traj, durations, _ = load_cycle()
        return model, traj, durations
    from characterization.gait.multicontact_artifact import load_contact_cycle

    c = load_contact_cycle(path)
    return c.model, c.trajectory, c.durations


def controllers(path: Path | None = None, swing_phase: str = DEFAULT_SWING_PHASE
                ) -> tuple[dict[str, Controller], Any]:
    """The two controllers of the cycle (:func:`cycle`; ``swing_phase``: how they measure
    the swing's phase), and its in-process simulator."""
    model, traj, durations = cycle(path)
    gait = contact_gait_of(model, traj, durations)
    sim = loop_simulator(model, gait, GAINS)
    leg = LegKinematics.of(model)
    p = model.device.prosthesis
    pd = ContactPhasePD(controller_tables(sim, leg, traj), leg,
                        (p.knee.gear_ratio.value, p.ankle.gear_ratio.value),
                        (p.knee.torque_limit.value, p.ankle.torque_limit.value),
                        swing_phase=swing_phase)
    return {"clfqp": contact_clfqp(model, gait, traj, swing_phase=swing_phase),
            "contact-pd": pd}, (sim, traj)


def following(path: Path, speed: float, swing_phase: str = DEFAULT_SWING_PHASE
              ) -> tuple[dict[str, Controller], Any]:
    """The two controllers following the person's speed over the library at ``path``,
    started at ``speed`` (m/s), and the in-process simulator of its curves there with the
    cycle's start at that speed."""
    from characterization.gait.library import load_gait_library, start_at
    from orchestrator.cosim.following import speed_following

    lib = load_gait_library(path)
    sim = loop_simulator(lib.model, lib.gait_at(speed), GAINS)
    return ({c: speed_following(lib, c, speed, swing_phase, sim.cl)
             for c in ("clfqp", "contact-pd")}, (sim, start_at(lib, speed)))


def walk_measurements(ctl: Controller, sim: Any, traj: Any, steps: int
                      ) -> list[ProsthesisMeasurement]:
    """What ``ctl`` read over ``steps`` steps of the cycle (``traj``: its trajectories, or
    the (q0, qd0) to start from; up to a fall, said on a line: its ticks still measure the
    controller's cost)."""
    ctl.reset()
    q0, qd0 = traj if isinstance(traj, tuple) else start_state(traj)
    plant = SimulatorPlant(sim, q0, qd0, GRAPH.domains[0])
    read: list[ProsthesisMeasurement] = []
    while plant.run.steps < steps:
        m = measurement(plant.observe())
        read.append(m)
        plant.actuate(ctl.tick(m).torque)
        if plant.fall is not None:
            print(f"{ctl.name} fell on the cycle after {len(read)} ticks: "
                  f"{plant.fall.message()}; timed up to there")
            break
        plant.advance()
    return read


def time_ticks(ctl: Controller, read: list[ProsthesisMeasurement]) -> np.ndarray:
    """Each tick's duration (us) over the measurements, from a reset controller."""
    ctl.reset()
    out = np.empty(len(read))
    clock = time.perf_counter_ns
    gc.disable()
    try:
        for k, m in enumerate(read):
            t0 = clock()
            ctl.tick(m)
            out[k] = clock() - t0
    finally:
        gc.enable()
    return out * 1e-3


def measure(ctl: Controller, read: list[ProsthesisMeasurement], repeats: int
            ) -> dict[str, Any]:
    stance = np.array([m.contact for m in read])
    medians, p99s, st_med, sw_med = [], [], [], []
    for _ in range(repeats):
        us = time_ticks(ctl, read)
        medians.append(float(np.median(us)))
        p99s.append(float(np.percentile(us, 99)))
        st_med.append(float(np.median(us[stance])))
        sw_med.append(float(np.median(us[~stance])))
    return {"ticks": len(read), "repeats": repeats, "median_us": float(np.median(medians)),
            "median_range_us": [min(medians), max(medians)], "p99_us": float(np.median(p99s)),
            "stance_median_us": float(np.median(st_med)),
            "swing_median_us": float(np.median(sw_med)), "target_us": 40.0}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cycle", type=Path, help="multi-contact gait file (default: the "
                    "committed openOFM cycle)")
    ap.add_argument("--library", type=Path, help="gait library (hpcosim gait library): the "
                    "controllers following the person's speed over it")
    ap.add_argument("--speed", type=float, default=0.9, help="m/s, with --library")
    ap.add_argument("--swing-phase", choices=SWING_PHASES, default=DEFAULT_SWING_PHASE)
    ap.add_argument("--steps", type=int, default=6)
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--json", type=Path)
    a = ap.parse_args()
    ctls, (sim, traj) = (following(a.library, a.speed, a.swing_phase) if a.library else
                         controllers(a.cycle, a.swing_phase))
    rows = {name: measure(c, walk_measurements(c, sim, traj, a.steps), a.repeats)
            for name, c in ctls.items()}
    print("| tick | ticks x repeats | median (us) | range over repeats | p99 | stance | swing |")
    print("|---|---|---|---|---|---|---|")
    for name, r in rows.items():
        lo, hi = r["median_range_us"]
        print(f"| {name} | {r['ticks']} x {a.repeats} | {r['median_us']:.1f} | "
              f"{lo:.1f}-{hi:.1f} | {r['p99_us']:.1f} | {r['stance_median_us']:.1f} | "
              f"{r['swing_median_us']:.1f} |")
        print(f"{name}: median <= 40 us: {'holds' if r['median_us'] <= 40 else 'FAILS'}")
    if a.json is not None:
        a.json.write_text(json.dumps({"controllers": rows, "machine": platform.machine(),
                                      "python": platform.python_version()}, indent=2))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
