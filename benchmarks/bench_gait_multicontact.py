"""Benchmark: the multi-contact fit (``gait fit --domains multicontact``; issue 37 target: a
3-stride take in <= 60 s on these 2-core machines) on openOFM's Vicon walk (tests/data: one
complete stride; the NLP's size does not depend on the number of strides, which only average
the targets) or, with ``--take gaitalytics``, gaitalytics' treadmill walk (10 strides, a
force plate under each belt: the fit also tracks the plates).

The walker is the take's person (75 kg, 1.83 m, stored with the steps) on the device they
would wear (its pylon cut to their leg, its foot their foot's size), as ``gait fit`` uses by
default.  Per repeat: targets from the steps, NLP construction and the IPOPT solves (three,
and the fourth of the angles' limit where it runs) (wall), the iterations; printed: median
and spread, what the fourth solve did, and the comparison with the take (speed, stride,
double supports, angle RMS).

    PYTHONPATH=. python benchmarks/bench_gait_multicontact.py [--take openofm|gaitalytics]
        [--repeats 3] [--json out.json]
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
import time
from pathlib import Path

from characterization.gait.fit import worn_device
from characterization.gait.multicontact import GRAPH, fit_multicontact, targets_from_steps
from characterization.gait.multicontact_summary import gait_summary, take_summary
from characterization.gait.person_check import StanceForce, check_person
from characterization.mocap.session import process_session
from characterization.mocap.steps_artifact import load_steps, plate_forces, steps_subject
from hp_model.config import default_device_path, load_device
from hp_model.human_prosthesis import HumanProsthesisModel
from hp_model.json_io import write_json

DATA = Path(__file__).resolve().parent.parent / "tests" / "data"
#: take name -> (its file, its mapping)
TAKES = {
    "openofm": (DATA / "openofm-walk" / "dynamic.c3d", DATA / "openofm-walk" / "mapping.toml"),
    "gaitalytics": (DATA / "gaitalytics-treadmill" / "treadmill_events.c3d",
                    DATA / "gaitalytics-treadmill" / "mapping.toml"),
}


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--take", choices=sorted(TAKES), default="openofm")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--json", type=Path, help="also write the figures to this JSON file")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "steps.npz"
        take, mapping = TAKES[args.take]
        process_session([take], out, mapping=mapping, with_figures=False)
        steps = load_steps(out)
    stored = steps_subject(steps, str(take))
    if stored is None:
        raise SystemExit("the steps carry no subject")
    person = stored[0]
    device, _ = worn_device(person, load_device(default_device_path()))  # with its armature
    model = HumanProsthesisModel(person, device, graph=GRAPH)
    model.numeric()  # compiled once, outside the timing
    walls, iters = [], []
    for k in range(args.repeats):
        t0 = time.perf_counter()
        targets = targets_from_steps(steps, model)
        r = fit_multicontact(model, targets)
        walls.append(time.perf_counter() - t0)
        iters.append(r.iterations)
        print(f"repeat {k + 1}: {walls[-1]:.1f} s, {r.status}, {r.iterations} iterations; "
              f"angles' limit: {r.stats.get('angle_limit_stage')}")
    plates = plate_forces(steps)  # the take's plates, where it has them
    grf, weight = ({f: StanceForce(fx=m.fx, fz=m.fz) for f, m in plates[0].items()},
                   plates[1]) if plates else ({}, float("nan"))
    check = check_person(take_summary(targets, "take", grf, weight), gait_summary(model, r))
    rows = {row.criterion: row.error for row in check.rows}
    med = statistics.median(walls)
    print(f"multi-contact fit: median {med:.1f} s (min {min(walls):.1f}, max {max(walls):.1f}) "
          f"over {args.repeats}; target <= 60 s")
    for name, err in rows.items():
        print(f"  {name}: {err:.3g}")
    if args.json:
        write_json(args.json, {"median_s": med, "walls_s": walls, "iterations": iters,
                               "check": check.to_json()})


if __name__ == "__main__":
    main()
