"""Verification: the accuracy of the production integration (the FMU's doStep = the
in-process ``HybridSimulator``, bit for bit) against a tight-tolerance reference run of the
same scenario, by the per-step restart criterion of ``tests/integration_accuracy.py`` (the
scenario, the reference and the criterion are described there): the largest state error
(inf-norm) and impact-time error over the impacts of a 20-step walk of the demo controller
``clfqp``; the reference's own error (Richardson: half its substeps); the free-running error
for transparency.  Target (issue 22): state error below 1e-6 at every impact.

Usage: PYTHONPATH=. python benchmarks/bench_accuracy.py [--steps 20] [--substeps 2]
       [--ref-substeps 64] [--json out.json]
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from dataclasses import replace
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # tests.* helpers

from hp_model.simulator import SimOptions
from tests.integration_accuracy import (
    CONTROLLER,
    REFERENCE,
    TARGET,
    Scenario,
    free_running,
    per_step,
    run,
    worst,
)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--steps", type=int, default=20)
    ap.add_argument("--substeps", type=int, default=SimOptions().substeps,
                    help="the integrator under test (default: the FMU's default)")
    ap.add_argument("--ref-substeps", type=int, default=REFERENCE.substeps)
    ap.add_argument("--json", help="also write the figures to this JSON file")
    a = ap.parse_args()

    t0 = time.perf_counter()
    sc = Scenario()
    refo = replace(REFERENCE, substeps=a.ref_substeps)
    ref = run(sc, refo, a.steps)
    if ref.fall or len(ref.impacts) < a.steps:
        raise SystemExit(f"the reference run did not walk {a.steps} steps: {ref.fall}")
    half = per_step(sc, ref, replace(refo, substeps=refo.substeps // 2))
    prod_opt = replace(SimOptions(), substeps=a.substeps)
    rows = per_step(sc, ref, prod_opt)
    free = free_running(ref, run(sc, prod_opt, a.steps, checkpoints=False))
    w, wh, wf = worst(rows), worst(half), worst(free)
    out = {
        "steps": a.steps, "controller": CONTROLLER, "substeps": a.substeps,
        "ref_substeps": refo.substeps, "target_state_error": TARGET,
        "per_step": w, "per_step_rows": rows,
        "reference_half": wh, "reference_error_estimate": wh["state"] / 15.0,
        "free_running": wf, "free_running_rows": free,
        "met": bool(w["state"] < TARGET), "seconds": time.perf_counter() - t0,
    }
    print(f"{CONTROLLER}, demo gait, {a.steps} steps; reference RK4 x{refo.substeps} "
          f"(its error ~ {out['reference_error_estimate']:.2g}: x{refo.substeps // 2} is "
          f"{wh['state']:.2g} from it)")
    print(f"per-step restart, RK4 x{a.substeps}: max state error {w['state']:.3g} "
          f"(q {w['q']:.3g}, qd {w['qd']:.3g}), impact time {w['t']:.3g} s; "
          f"target < {TARGET:g}: {'met' if out['met'] else 'NOT met'}")
    print(f"free running, RK4 x{a.substeps}: max state error {wf['state']:.3g}, impact time "
          f"{wf['t']:.3g} s (the loop's sensitivity, not the integrator's)")
    print(f"{out['seconds']:.0f} s")
    if a.json:
        Path(a.json).write_text(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()
