"""Benchmark: the two-domain 12-DOF PHZD optimization from the regression's initial guess
(issue 4 target: under 60 s median), on the synthetic subject's steps (37 strides, seed 1;
``--source model``, the default subject walking the packaged reference gait, or
``--source template``, the kinematic template).

Per repeat: NLP construction + IPOPT solve (wall), iterations, and the share of the solve
spent evaluating functions and derivatives (CasADi's t_wall_nlp_* statistics); then the
closed-loop verification (20 steps + return map).  Printed once: the optimized outputs'
RMS from the data (+ offsets), and for the model source from the reference gait.

    PYTHONPATH=. python benchmarks/bench_gait.py [--repeats 3] [--source model|template]
        [--json out.json]
"""

from __future__ import annotations

import argparse
import json
import statistics
import tempfile
import time
from pathlib import Path

import numpy as np

import hp_model
from characterization.gait.design import build_gait
from characterization.gait.fit import output_rms, regress_steps, verify_gait
from characterization.gait.phzd import PHZDOptions, optimize_gait
from characterization.mocap.mapping import default_mapping
from characterization.mocap.pipeline import process_take, to_artifact
from characterization.mocap.synthetic_subject import SynthOptions, reference_gait, synthesize
from hp_model import bezier
from hp_model.domains import PAPER_DOMAINS


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--source", choices=("model", "template"), default="model")
    ap.add_argument("--json", type=Path, help="also write the figures to this JSON file")
    args = ap.parse_args()
    model = hp_model.load_model()
    coef = {d: model.hip_progress_coefficients(d) for d in PAPER_DOMAINS}
    with tempfile.TemporaryDirectory():
        s = synthesize(model, SynthOptions(n_strides=37, seed=1, source=args.source))
        steps = to_artifact(process_take(s.take, default_mapping(), coef))
    reg = regress_steps(model, steps, 5)
    opt = PHZDOptions()
    rows = []
    for _ in range(args.repeats):
        t0 = time.perf_counter()
        r = optimize_gait(model, reg.targets, opt)
        total = time.perf_counter() - t0
        fe = sum(v for k, v in r.stats.items() if k.startswith("t_wall_nlp"))
        t1 = time.perf_counter()
        gait = build_gait(model, r, reg.targets, opt)
        v = verify_gait(model, gait)
        rows.append((total, r.solve_seconds, r.iterations, fe / r.solve_seconds,
                     time.perf_counter() - t1, r.status, v["spectral_radius"]))
    med = statistics.median
    print("| quantity | median | min | max |\n|---|---|---|---|")
    figures = {}
    for i, name in ((0, "build + solve (s)"), (1, "IPOPT solve (s)"), (2, "iterations"),
                    (3, "share of solve in function/derivative evaluation"),
                    (4, "verification: 20 steps + return map (s)")):
        xs = [row[i] for row in rows]
        figures[name] = {"median": med(xs), "min": min(xs), "max": max(xs)}
        print(f"| {name} | {med(xs):.3g} | {min(xs):.3g} | {max(xs):.3g} |")
    if args.json:
        args.json.write_text(json.dumps({"source": args.source, "repeats": args.repeats,
                                         "status": str(rows[0][5]),
                                         "spectral_radius": float(rows[0][6]),
                                         "figures": figures}, indent=1))
    print(f"\nstatus {rows[0][5]}; return-map spectral radius {rows[0][6]:.2g}; "
          f"repeats {args.repeats}; source {args.source}")
    tau = np.linspace(0.0, 1.0, 201)
    for d, x in output_rms(gait).items():
        line = f"{d}: outputs vs data + offsets, RMS deg {np.round(np.degrees(x), 2)}"
        if args.source == "model":
            ref = reference_gait(model).params[d].alpha
            e = bezier.evaluate(gait.params[d].alpha, tau) - bezier.evaluate(ref, tau)
            line += f"; vs the reference gait {np.round(np.degrees(np.sqrt(np.mean(e**2, 0))), 2)}"
        print(line)


if __name__ == "__main__":
    Path(".").resolve()
    main()
