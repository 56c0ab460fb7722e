"""Benchmark: socket-force playback of 20 steps plus the force-tube fit, and the per-frame
F_s computation (our compiled ``socket_ps``) against the same computation with Pinocchio.

1. ``fit_force_tube`` end to end (checks, 20 playbacks - Bezier fit, zero-dynamics start,
   full-model simulation at 1 kHz with RK4, F_s per frame - the foot-marker interval, the 6
   LPs, certificate and credibility), repeated; median and spread; playback and tube parts
   separately.  Target (issue): < 5 s in total.  The figure and the report are timed once.
2. Per frame: F_s = (J_s D^-1 J_s^T)^-1 J_s D^-1 (H - B u - J_f^T lam_f) on every frame of
   the played-back steps, (a) ``socket_ps`` generated C through preallocated buffers,
   (b) Pinocchio 4 (CRBA, RNEA, frame Jacobian) + numpy solves
   (:class:`tests.playback_helpers.PinocchioSocket`), in the same run, interleaved repeats.
   Target: ours no slower.  The two must agree (relative 1e-8), checked.
3. ``--accuracy``: the estimate against the model-generated truth
   (:mod:`characterization.tube.playback_truth`) for a few angle-noise levels.

    PYTHONPATH=. python benchmarks/bench_playback.py [--repeats 7] [--steps 20]
        [--gait tests/data/playback/gait_synthetic.json] [--steps-file steps.npz] [--accuracy]
        [--json out.json]

Without ``--steps-file`` the steps come from the model-generated subject (20 ps steps).
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import hp_model
from characterization.mocap.steps_artifact import load_steps
from characterization.tube.playback import (
    PlaybackOptions,
    TubeOptions,
    fit_force_tube,
    socket_forces,
    write_outputs,
)
from characterization.tube.playback_truth import TruthOptions, synthesize
from hp_model.gait_artifact import load_gait
from tests.playback_helpers import (
    PinocchioSocket,
    relative_rms_errors,
    tube_excess,
)

DEFAULT_GAIT = Path(__file__).resolve().parents[1] / "tests/data/playback/gait_synthetic.json"


def stats(v: list[float], scale: float = 1.0) -> str:
    a = np.array(v) * scale
    return (f"median {statistics.median(a):8.3f}  min {a.min():8.3f}  max {a.max():8.3f}  "
            f"(n = {a.size})")


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--repeats", type=int, default=7)
    ap.add_argument("--steps", type=int, default=20)
    ap.add_argument("--degree", type=int, default=3)
    ap.add_argument("--gait", type=Path, default=DEFAULT_GAIT)
    ap.add_argument("--steps-file", type=Path, default=None)
    ap.add_argument("--frame-repeats", type=int, default=5)
    ap.add_argument("--accuracy", action="store_true")
    ap.add_argument("--json", type=Path, help="also write the figures to this JSON file")
    args = ap.parse_args()

    model = hp_model.load_model()
    gait = load_gait(args.gait, model.parameter_hash())
    if args.steps_file is not None:
        steps = load_steps(args.steps_file)
        src = str(args.steps_file)
    else:
        t0 = time.perf_counter()
        steps = synthesize(model, gait, TruthOptions(n_ps=args.steps, seed=3, sigma=0.03)).steps
        src = f"model-generated subject ({time.perf_counter() - t0:.1f} s to synthesize)"
    print(f"steps: {src}; gait {args.gait.name}; degree-{args.degree} tube over "
          f"{args.steps} ps steps")

    # 1. playback + tube, end to end
    res = fit_force_tube(model, gait, steps, TubeOptions(degree=args.degree),
                         args.steps)  # warm-up (compiles)
    total, play, tube = [], [], []
    for _ in range(args.repeats):
        t0 = time.perf_counter()
        res = fit_force_tube(model, gait, steps, TubeOptions(degree=args.degree), args.steps)
        total.append(time.perf_counter() - t0)
        play.append(res.seconds["playback"])
        tube.append(res.seconds["tube"])
    n_frames = sum(len(s.tau) for s in res.playback.steps)
    print(f"\n1. playback of {len(res.playback.steps)} steps ({n_frames} frames of F_s at "
          f"{1 / PlaybackOptions().dt:.0f} Hz) + tube fit, s:")
    print(f"   total     {stats(total)}   target < 5 s")
    print(f"   playback  {stats(play)}")
    print(f"   tube      {stats(tube)}")
    with tempfile.TemporaryDirectory() as tmp:
        t0 = time.perf_counter()
        write_outputs(Path(tmp) / "tube.json", res)
        print(f"   figure + report + tube file (once): {time.perf_counter() - t0:.3f} s")

    # 2. per-frame F_s: ours vs Pinocchio, same frames, interleaved
    q = np.concatenate([s.q for s in res.playback.steps])
    qd = np.concatenate([s.qd for s in res.playback.steps])
    u = np.concatenate([s.u for s in res.playback.steps])
    lam_f = np.concatenate([s.lam[:, 0:3] for s in res.playback.steps])
    oracle = PinocchioSocket(model)
    ours_t, pin_t = [], []
    for _ in range(args.frame_repeats):
        t0 = time.perf_counter()
        F_ours = socket_forces(model, q, qd, u, lam_f)
        t1 = time.perf_counter()
        F_pin = np.array([oracle(q[j], qd[j], u[j], lam_f[j]) for j in range(len(q))])
        t2 = time.perf_counter()
        ours_t.append((t1 - t0) / len(q))
        pin_t.append((t2 - t1) / len(q))
    err = float(np.abs(F_ours - F_pin).max() / np.abs(F_pin).max())
    print(f"\n2. F_s per frame ({len(q)} frames x {args.frame_repeats} repeats), us:")
    print(f"   ours (socket_ps, generated C)  {stats(ours_t, 1e6)}")
    print(f"   Pinocchio 4 + numpy            {stats(pin_t, 1e6)}")
    print(f"   ratio Pinocchio / ours: {statistics.median(pin_t) / statistics.median(ours_t):.1f}"
          f"; max relative difference {err:.1e}")
    if err > 1e-8:
        raise SystemExit(f"ours and Pinocchio disagree ({err:.1e})")
    if args.json:
        def st(v: list[float], scale: float = 1.0) -> dict[str, float]:
            return {"median": scale * statistics.median(v), "min": scale * min(v),
                    "max": scale * max(v)}

        args.json.write_text(json.dumps({
            "steps": len(res.playback.steps), "frames": n_frames, "repeats": args.repeats,
            "fit_s": {"total": st(total), "playback": st(play), "tube": st(tube)},
            "per_frame_us": {"ours": st(ours_t, 1e6), "pinocchio": st(pin_t, 1e6)},
            "max_relative_difference": err}, indent=1))

    # 3. accuracy against the truth
    if args.accuracy:
        print("\n3. estimate vs truth, worst step: RMS error over [tau_lo, tau_hi] / peak "
              "|F_s| (%)")
        print("   case                      F_x     F_z     M_y   truth outside tube (% peak)")
        for name, opt in (("interior, no noise", TruthOptions(seed=3, sigma=0.03)),
                          ("start, no noise", TruthOptions(seed=1, sigma=0.02,
                                                           perturb="start")),
                          ("interior, 0.02 deg noise", TruthOptions(seed=3, sigma=0.03,
                                                                    noise_deg=0.02)),
                          ("interior, 0.05 deg noise", TruthOptions(seed=3, sigma=0.03,
                                                                    noise_deg=0.05)),
                          ("interior, 0.1 deg noise", TruthOptions(seed=3, sigma=0.03,
                                                                   noise_deg=0.1))):
            take = synthesize(model, gait, opt)
            for mg in (PlaybackOptions().fit_margin, 0.0, None):
                r = fit_force_tube(model, gait, take.steps, TubeOptions(degree=args.degree),
                                   options=PlaybackOptions(fit_margin=mg))
                e = 100 * relative_rms_errors(r, take).max(axis=0)
                x = 100 * tube_excess(r, take).max()
                print(f"   {name:25s} {e[0]:6.2f}  {e[1]:6.2f}  {e[2]:6.2f}   {x:6.2f}   "
                      f"(fit margin {mg}{' = whole step' if mg is None else ''})")


if __name__ == "__main__":
    main()
