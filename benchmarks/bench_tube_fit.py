"""Benchmark: the force-tube fit for 20 synthetic deviation profiles x 150 samples, degree 3.

Timed per repeat: ``fit_bounds`` (the 6 LPs alone, constraint generation), the same LPs
without constraint generation (full 3000-row LPs), and ``fit_tube`` (LPs + certificate +
credibility: compression refit, leave-one-out refits); the figure and the Markdown snippet
are timed separately.  Target (issue "force tube"): playback of 20 steps + tube fit < 5 s,
so the fit should stay well under 1 s.

    PYTHONPATH=. python benchmarks/bench_tube_fit.py [--repeats 15] [--steps 20] [--samples 150]
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

from characterization.tube.fit import (
    credibility_markdown,
    fit_bounds,
    fit_tube,
    save_tube_figure,
)
from hp_model import bezier

TAU_LO, TAU_HI = 0.15, 0.85


def profiles(n_steps: int, n: int, seed: int = 0) -> list[tuple[np.ndarray, np.ndarray]]:
    rng = np.random.default_rng(seed)
    scale = np.array([30.0, 80.0, 5.0])
    base = rng.normal(size=(3, 6)) * scale[:, None]
    out = []
    for _ in range(n_steps):
        tau = np.sort(rng.uniform(TAU_LO, TAU_HI, n))
        tau[0], tau[-1] = TAU_LO, TAU_HI
        a = base + 0.15 * rng.normal(size=base.shape) * scale[:, None]
        y = bezier.evaluate(a, (tau - TAU_LO) / (TAU_HI - TAU_LO))
        out.append((tau, y + 0.02 * rng.normal(size=y.shape) * scale))
    return out


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--repeats", type=int, default=15)
    ap.add_argument("--steps", type=int, default=20)
    ap.add_argument("--samples", type=int, default=150)
    ap.add_argument("--degree", type=int, default=3)
    ap.add_argument("--json", type=Path, help="also write the figures to this JSON file")
    args = ap.parse_args()
    nominal = np.zeros((3, 6))
    rows: dict[str, list[float]] = {k: [] for k in (
        "6 LPs (constraint generation)", "6 LPs (full)", "fit_tube (all)", "figure (png)",
        "markdown")}
    with tempfile.TemporaryDirectory() as tmp:
        for r in range(args.repeats + 1):  # the first repeat warms imports and caches
            p = profiles(args.steps, args.samples, seed=r)
            t0 = time.perf_counter()
            fit_bounds(p, TAU_LO, TAU_HI, args.degree)
            t1 = time.perf_counter()
            fit_bounds(p, TAU_LO, TAU_HI, args.degree, reduce=False)
            t2 = time.perf_counter()
            tube = fit_tube(p, nominal, TAU_LO, TAU_HI, args.degree)
            t3 = time.perf_counter()
            save_tube_figure(Path(tmp) / "fig5.png", tube, p)
            t4 = time.perf_counter()
            credibility_markdown(tube.credibility)
            t5 = time.perf_counter()
            if r == 0:
                continue
            for k, v in zip(rows, (t1 - t0, t2 - t1, t3 - t2, t4 - t3, t5 - t4), strict=True):
                rows[k].append(v)
    cr = tube.credibility
    print(f"{args.steps} profiles x {args.samples} samples, degree {args.degree}, "
          f"{args.repeats} repeats (different data each)")
    print(f"{'stage':32s} {'median ms':>10s} {'min ms':>8s} {'max ms':>8s}")
    for k, v in rows.items():
        ms = np.array(v) * 1e3
        print(f"{k:32s} {statistics.median(ms):10.1f} {ms.min():8.1f} {ms.max():8.1f}")
    if args.json:
        args.json.write_text(json.dumps({
            "steps": args.steps, "samples": args.samples, "degree": args.degree,
            "repeats": args.repeats,
            "stages_ms": {k: {"median": 1e3 * statistics.median(v), "min": 1e3 * min(v),
                              "max": 1e3 * max(v)} for k, v in rows.items()}}, indent=1))
    print(f"last fit: k_tube = {cr['a_posteriori']['k_tube']}, "
          f"eps_tube = {cr['a_posteriori']['epsilon_tube']:.3f}, "
          f"LOO coverage = {cr['leave_one_out']['coverage']:.2f}")


if __name__ == "__main__":
    main()
