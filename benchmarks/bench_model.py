"""Benchmark: evaluating the 12-DOF model from Python, against Pinocchio in the same run.

Measures, per call from Python (median and spread over repeated batches):
  - Pinocchio crba + rnea (the reference: D and H only)
  - ours, compiled C: D, H, J, Jdot qd together (``terms_ps``)
  - ours, compiled C: constrained dynamics qdd and the 6 wrenches (``dyn_ps``)
  - Pinocchio crba + rnea + a dense numpy KKT solve (the same answer as ``dyn_ps``)
  - ours through the CasADi SX interpreter (no compiler), for scale

Usage: python benchmarks/bench_model.py [--repeats 15] [--calls 2000] [--json out.json]
"""

from __future__ import annotations

import argparse
import json
import platform
import time

import numpy as np
import pinocchio as pin

import hp_model
from hp_model.urdf import to_urdf


def batches(fn, calls: int, repeats: int) -> np.ndarray:
    fn()  # warm up
    out = []
    for _ in range(repeats):
        t = time.perf_counter()
        for _ in range(calls):
            fn()
        out.append((time.perf_counter() - t) / calls * 1e6)
    return np.array(out)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=15)
    ap.add_argument("--calls", type=int, default=2000)
    ap.add_argument("--json", help="also write the figures to this JSON file")
    a = ap.parse_args()

    model = hp_model.load_model()
    fs = model.numeric("c")
    sx = model.numeric("sx")
    pm = pin.buildModelFromXML(to_urdf(model.tree))
    pm.gravity.linear = np.array([0.0, 0.0, -model.tree.gravity])
    pd = pm.createData()

    rng = np.random.default_rng(1)
    q = rng.normal(scale=0.3, size=12)
    q[1] += 0.9
    qd = rng.normal(size=12)
    u = rng.normal(size=6)
    zero = np.zeros(12)
    B = model.B
    J = fs["terms_ps"](q, qd)[2].copy()
    Jdqd = fs["terms_ps"](q, qd)[3].copy()
    K = np.zeros((18, 18))

    def pin_terms():
        pin.crba(pm, pd, q)
        pin.rnea(pm, pd, q, qd, zero)

    def pin_kkt():
        M = pin.crba(pm, pd, q)
        M = np.triu(M) + np.triu(M, 1).T
        h = pin.rnea(pm, pd, q, qd, zero)
        K[:12, :12] = M
        K[:12, 12:] = -J.T
        K[12:, :12] = J
        return np.linalg.solve(K, np.r_[B @ u - h, -Jdqd])

    terms, dyn = fs["terms_ps"], fs["dyn_ps"]
    dyn.inputs[0][:], dyn.inputs[1][:], dyn.inputs[2][:] = q, qd, u
    cases = {
        "pinocchio crba+rnea": pin_terms,
        "ours C: D,H,J,Jdot qd": lambda: terms(q, qd),
        "ours C: constrained dynamics": lambda: dyn(q, qd, u),
        "ours C: constrained dynamics (in place)": dyn.call_inplace,
        "pinocchio crba+rnea + numpy KKT": pin_kkt,
        "ours SX interpreter: D,H,J,Jdot qd": lambda: sx["terms_ps"](q, qd),
        "ours SX interpreter: constrained dynamics": lambda: sx["dyn_ps"](q, qd, u),
    }
    ref = None
    results = {}
    print(f"machine: {platform.processor() or platform.machine()}, python "
          f"{platform.python_version()}, {a.repeats} batches x {a.calls} calls")
    print(f"{'case':44s} {'median us':>10s} {'min-max us':>16s} {'/ pinocchio':>12s}")
    for name, fn in cases.items():
        s = batches(fn, a.calls, a.repeats)
        med = float(np.median(s))
        ref = med if ref is None else ref
        results[name] = {"median_us": med, "min_us": float(s.min()), "max_us": float(s.max()),
                         "ratio_to_pinocchio_crba_rnea": med / ref}
        print(f"{name:44s} {med:10.2f} {s.min():7.2f}-{s.max():<8.2f} {med / ref:12.2f}")
    if a.json:
        with open(a.json, "w") as f:
            json.dump(results, f, indent=2)


if __name__ == "__main__":
    main()
