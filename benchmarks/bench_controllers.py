"""Benchmark: per-tick cost of the prosthesis controllers on a real stance trajectory.

10,000 consecutive ticks (1 kHz) along the gait's prosthesis-stance collocation trajectory
(th_pk, th_pa and their rates interpolated at 1 kHz, small noise added, repeated with time
running on), for every controller of the registry; then the
bare piqp update + solve of the very QPs the relaxed controller solved, in the same run,
and the ratio of the relaxed tick to the bare solve.  Prints a markdown table.

The machine is shared and noisy: quote ratios; rerun for absolutes.

Usage: python benchmarks/bench_controllers.py [--gait gait.json [--tube tube.json]]
                                               [--ticks 10000] [--repeats 3] [--json out.json]
Without --gait the tests' committed template gait; without --tube the tube is
+-(40 N, 60 N, 8 N m) about the gait's nominal socket force (as in the tests).
"""

from __future__ import annotations

import argparse
import gc
import json
import platform
import sys
import time
from collections import Counter
from pathlib import Path

import numpy as np
import piqp

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # tests.* helpers

import hp_model
from hp_model.force_tube import ForceTube, load_tube
from hp_model.gait_artifact import Gait, load_gait
from prosthesis_controller import (
    CONTROLLERS,
    ControllerContext,
    ControllerName,
    QpOutcome,
    make_controller,
)
from tests.controller_support import stance_ticks

HALF = (40.0, 60.0, 8.0)  # tube half-widths, N, N, N m (as in the tests)


def template_gait(model) -> Gait:
    """The tests' committed template gait (tests/data/gaits, see its NOTICE)."""
    from tests.committed_gaits import RECIPES, ROOT

    return load_gait(ROOT / RECIPES["template"].path, model.parameter_hash())


def time_ticks(ctl, meas, u0) -> tuple[np.ndarray, Counter]:
    ctl.reset(u0)
    ts = np.empty(len(meas))
    modes: Counter = Counter()
    clock = time.perf_counter_ns
    for k, m in enumerate(meas):
        t0 = clock()
        out = ctl.tick(m)
        ts[k] = clock() - t0
        modes[out.diagnostics.mode] += 1
    return ts / 1e3, modes


def bare_piqp(ctl, qps) -> np.ndarray:
    """update + solve of recorded QPs on a fresh solver with the controller's settings."""
    s = piqp.DenseSolver()
    st, cs = s.settings, ctl._solver.settings
    for k in ("eps_abs", "eps_rel", "eps_duality_gap_abs", "eps_duality_gap_rel"):
        setattr(st, k, getattr(cs, k))
    P, c, G, h, xl, xu = qps[0]
    s.setup(P=P, c=c, G=G, h_l=np.full(len(h), -np.inf), h_u=h, x_l=xl, x_u=xu)
    ts = np.empty(len(qps))
    clock = time.perf_counter_ns
    for k, (P, c, G, h, xl, xu) in enumerate(qps):
        t0 = clock()
        s.update(P=P, c=c, G=G, h_u=h, x_l=xl, x_u=xu)
        s.solve()
        _ = s.result.x
        ts[k] = clock() - t0
    return ts / 1e3


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--gait", help="gait artifact (default: optimize the test template)")
    ap.add_argument("--tube", help="force-tube artifact of --gait (default: +-HALF about F*)")
    ap.add_argument("--ticks", type=int, default=10_000)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--no-gc", action="store_true", help="disable the garbage collector")
    ap.add_argument("--json", help="also write the figures to this JSON file")
    a = ap.parse_args()
    if a.tube and not a.gait:
        ap.error("--tube needs the --gait it was fitted for")

    model = hp_model.load_model()
    gait = load_gait(a.gait, model.parameter_hash()) if a.gait else template_gait(model)
    if a.tube:
        tube = load_tube(a.tube, gait.hash())
    else:
        h = np.array(HALF)[:, None] * np.ones((1, 2))
        tube = ForceTube(gait_hash=gait.hash(), tau_lo=0.0, tau_hi=1.0,
                         nominal=gait.socket_nominal, lower=-h, upper=h)
    ctx = ControllerContext(gait, tube, model)
    meas, u0 = stance_ticks(model, gait, a.ticks)
    ctls = {n: make_controller(n, gait, tube, model, context=ctx) for n in ControllerName}

    # the QPs the relaxed controller solves along this run (recorded in an untimed pass)
    rec = ctls["clfqp"]
    rec.reset(u0)
    qps = []
    for m in meas:
        out = rec.tick(m)
        if out.diagnostics.qp_status in (QpOutcome.SOLVED, QpOutcome.FAILED):
            qps.append(rec.qp_data())  # copies, Fortran-ordered matrices

    if a.no_gc:
        gc.disable()
    times: dict[str, list[np.ndarray]] = {n: [] for n in [*ControllerName, "piqp"]}
    modes: dict[str, Counter] = {}
    for _ in range(a.repeats):
        for n, c in ctls.items():
            ts, md = time_ticks(c, meas, u0)
            times[n].append(ts)
            modes[n] = md
        times["piqp"].append(bare_piqp(rec, qps))
    gc.enable()

    rows = {}
    for n, lst in times.items():
        ts = np.concatenate(lst)
        rows[n] = {"median_us": float(np.median(ts)), "p99_us": float(np.percentile(ts, 99)),
                   "n": int(ts.size)}
    ratio = rows["clfqp"]["median_us"] / rows["piqp"]["median_us"]

    print(f"\n{a.ticks} consecutive 1 kHz ticks along the ps trajectory x {a.repeats} "
          f"repeats; tube {a.tube or f'+-{HALF}'}; {platform.processor() or platform.machine()}\n")
    print("| controller | median per tick (us) | p99 (us) | modes (last repeat) |")
    print("|---|---:|---:|---|")
    labels = {**{n: f"{n}: {e.description}" for n, e in CONTROLLERS.items()},
              "piqp": "bare piqp update + solve (relaxed QPs)"}
    for n in [*ControllerName, "piqp"]:
        r = rows[n]
        md = ", ".join(f"{k} {v}" for k, v in sorted(modes.get(n, {}).items())) or "-"
        print(f"| {labels[n]} | {r['median_us']:.1f} | {r['p99_us']:.1f} | {md} |")
    print(f"\nrelaxed tick / bare solve (medians): {ratio:.2f}x "
          f"(targets: median <= 40 us, p99 <= 150 us, ratio <= 2.5x)")
    if a.json:
        with open(a.json, "w") as f:
            json.dump({"rows": rows, "ratio": ratio, "ticks": a.ticks,
                       "repeats": a.repeats, "modes": {k: dict(v) for k, v in modes.items()}},
                      f, indent=2)


if __name__ == "__main__":
    main()
