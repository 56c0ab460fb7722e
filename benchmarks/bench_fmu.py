"""Benchmark: the human FMU (built C, stepped through fmpy) against the in-process Python
simulator, and the FMU build time.

  - build: ``build_fmu`` from the gait file (model, code generation, compile, zip);
  - one 1 ms doStep (one RK4 step whose first stage is the friction-cone check's
    evaluation, so four evaluations of the closed loop; event location when an impact falls
    in the step) through fmpy ``FMU2Slave.doStep``: median and p90 over a walking run whose
    prosthesis torques are the nominal-PD policy's torques of the Python run, replayed (so
    both integrate the same trajectory, impacts included); also the plain ctypes call
    without fmpy's wrapper, and a whole co-simulation exchange (set 2 inputs + doStep + get
    6 sensor outputs);
  - the in-process ``HybridSimulator`` over the same periods with the same replayed torques
    (mean per period: ``run`` does not expose single periods);
  - the ratio Python per period / FMU doStep.

Both graphs: the paper's (the gait given, default the tests' template gait, under the
nominal-PD policy's torques) and the multi-contact one (the committed openOFM cycle, under
the held oracle's torques).

Targets (issue 22): doStep median <= 15 us (at the accuracy bench_accuracy.py checks);
>= 10x faster than the Python simulator; build < 60 s.  Issue 37: the multi-contact FMU's
doStep <= 30 us.
The machines are shared: quote ratios.

Usage: PYTHONPATH=. python benchmarks/bench_fmu.py [--gait gait.json] [--cycle mc.json]
       [--periods 3000] [--json out.json]   (without --gait, the tests' committed template
       gait; without --cycle, the committed openOFM multi-contact cycle)
"""

from __future__ import annotations

import argparse
import ctypes
import json
import platform
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # tests.* helpers

import hp_model
from hp_model.domains import Domain
from hp_model.gait_artifact import load_gait, save_gait
from human_fmu import build_fmu
from tests.fmu_runner import HumanFMU, NominalPD
from tests.fmu_support import policy_table, python_run, simulator, start_state

SENSORS = ("knee_angle", "ankle_angle", "knee_velocity", "ankle_velocity", "foot_load", "tau")


def template_gait(model, path: Path) -> None:
    """The tests' committed template gait (tests/data/gaits, see its NOTICE), written to
    ``path``."""
    from hp_model.gait_artifact import load_gait
    from tests.committed_gaits import RECIPES, ROOT

    save_gait(path, load_gait(ROOT / RECIPES["template"].path, model.parameter_hash()))


def replayed_run(sim, q0, qd0, policy, periods: int) -> tuple[np.ndarray, Any, float]:
    """The simulator's run of ``periods`` under ``policy``, its torques, and the same run
    with the torques replayed: (torques (n, 2), the replayed run, its us per period)."""
    torques: list[np.ndarray] = []

    def record(t, st):
        torques.append(np.array(policy(t, st), float))  # a copy: policies may reuse buffers
        return torques[-1]

    rec = sim.run(q0, qd0, Domain.PS, duration=periods * 1e-3, policy=record)
    if rec.fall is not None:
        raise SystemExit(f"the reference run fell: {rec.fall.message()}")
    n = rec.t.size - 1
    u = np.array(torques)
    replay = iter(u)
    t0 = time.perf_counter()
    rep = sim.run(q0, qd0, Domain.PS, duration=n * 1e-3, policy=lambda t, st: next(replay))
    py_per_period = (time.perf_counter() - t0) / n * 1e6
    assert np.array_equal(rep.q, rec.q)
    return u[:n], rep, py_per_period


def time_fmu(fmu_path: Path, u: np.ndarray, rep) -> dict[str, Any]:
    """doStep via fmpy, via plain ctypes, and a whole exchange, over the torques ``u``
    replayed; whether the FMU ends in the replayed run's state."""
    n = len(u)
    h = HumanFMU(str(fmu_path))
    f = h.fmu
    uv, sv = h.vrs(["u_knee", "u_ankle"]), h.vrs(SENSORS)
    qv = h.vrs([f"q[{i}]" for i in range(1, 13)])

    def fresh():
        f.reset()
        h.setup()

    fresh()
    step_ns = np.empty(n)
    pc = time.perf_counter_ns
    for k in range(n):
        f.setReal(uv, u[k].tolist())
        t1 = pc()
        f.doStep(k * 1e-3, 1e-3)
        step_ns[k] = pc() - t1
    q_end = np.array(f.getReal(qv))
    same = bool(np.array_equal(q_end, rep.q[-1]))

    fresh()
    lib = ctypes.CDLL(str(Path(h.unzipdir) / "binaries" / "linux64" / "hpcosim_human.so"))
    lib.fmi2DoStep.argtypes = [ctypes.c_void_p, ctypes.c_double, ctypes.c_double,
                               ctypes.c_int]
    lib.fmi2DoStep.restype = ctypes.c_int
    comp = f.component
    raw_ns = np.empty(n)
    for k in range(n):
        f.setReal(uv, u[k].tolist())
        t1 = pc()
        lib.fmi2DoStep(comp, k * 1e-3, 1e-3, 1)
        raw_ns[k] = pc() - t1

    fresh()
    cycle_ns = np.empty(n)
    for k in range(n):
        t1 = pc()
        f.setReal(uv, u[k].tolist())
        f.doStep(k * 1e-3, 1e-3)
        f.getReal(sv)
        cycle_ns[k] = pc() - t1
    h.free()
    step_us, raw_us, cycle_us = step_ns / 1e3, raw_ns / 1e3, cycle_ns / 1e3
    return {"fmu_doStep_us_median": float(np.median(step_us)),
            "fmu_doStep_us_p90": float(np.percentile(step_us, 90)),
            "fmu_doStep_us_mean": float(step_us.mean()),
            "fmu_doStep_ctypes_us_median": float(np.median(raw_us)),
            "fmu_exchange_us_median": float(np.median(cycle_us)),
            "same_final_state": same}


def paper(tmp: Path, gait_arg: Path | None, periods: int) -> dict[str, Any]:
    """The paper's graph: the FMU of the gait (default: the template gait) under the
    nominal-PD policy's torques."""
    model = hp_model.load_model()
    gait_path = gait_arg
    if gait_path is None:
        gait_path = tmp / "gait.json"
        print("the tests' template gait (tests/data/gaits)", flush=True)
        template_gait(model, gait_path)
    gait = load_gait(gait_path, model.parameter_hash())
    fmu_path = tmp / "human.fmu"
    info = build_fmu(gait_path, fmu_path)  # fresh: model, codegen, compile (no cache)
    sim = simulator(model, gait)
    pd = NominalPD(policy_table(model, gait, sim))
    q0, qd0 = start_state(gait)
    python_run(sim, pd, q0, qd0, duration=0.1)  # warm-up
    u, rep, py = replayed_run(
        sim, q0, qd0, lambda t, st: pd(st.domain, st.tau, st.q[10:12], st.qd[10:12]), periods)
    return {"periods": len(u), "impacts": len(rep.impacts), "build_s": info.seconds,
            "python_us_per_period": py, **time_fmu(fmu_path, u, rep)}


def multicontact(tmp: Path, periods: int, cycle: Path | None = None) -> dict[str, Any]:
    """The multi-contact graph: the FMU of the committed openOFM cycle (or of the
    multi-contact gait file ``cycle``) under the held oracle's torques."""
    from characterization.gait.contact_gait import GAINS, contact_gait_of, held_oracle
    from characterization.gait.contact_gait import start_state as cycle_start
    from orchestrator.cosim.contact_controllers import loop_simulator, tracked_gait
    from tests.multicontact_cycle import load_cycle

    if cycle is None:
        model, traj, durations, _ = load_cycle()
    else:
        from characterization.gait.multicontact_artifact import load_contact_cycle

        c = load_contact_cycle(cycle)
        model, traj, durations = c.model, c.trajectory, c.durations
    gait = contact_gait_of(model, traj, durations)
    fmu_path = tmp / "human_multicontact.fmu"
    info = build_fmu(tracked_gait(model, gait, traj, "openofm cycle"), fmu_path, model=model)
    sim = loop_simulator(model, gait, GAINS)
    q0, qd0 = cycle_start(traj)
    u, rep, py = replayed_run(sim, q0, qd0, held_oracle(sim.cl, gait.thetas(), sim.gains),
                              periods)
    return {"periods": len(u), "impacts": len(rep.impacts), "build_s": info.seconds,
            "python_us_per_period": py, **time_fmu(fmu_path, u, rep)}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--gait", type=Path, help="gait file (default: the tests' template gait)")
    ap.add_argument("--cycle", type=Path, help="multi-contact gait file (default: the "
                    "committed openOFM cycle)")
    ap.add_argument("--periods", type=int, default=3000)
    ap.add_argument("--json", help="also write the figures to this JSON file")
    a = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        fig = paper(Path(tmp), a.gait, a.periods)
        mc = multicontact(Path(tmp), a.periods, a.cycle)
    for f in (fig, mc):
        f["ratio_median"] = f["python_us_per_period"] / f["fmu_doStep_us_median"]
        f["ratio_mean"] = f["python_us_per_period"] / f["fmu_doStep_us_mean"]
    fig["multicontact"] = mc
    print(f"machine: {platform.processor() or platform.machine()}, python "
          f"{platform.python_version()}; {fig['periods']} periods of 1 ms, {fig['impacts']} "
          f"impacts (paper's graph), {mc['periods']}, {mc['impacts']} (multi-contact); FMU and "
          f"Python end in the same state: {fig['same_final_state']}, {mc['same_final_state']}")
    rows = []
    for label, f in (("", fig), ("multi-contact: ", mc)):
        b = f["build_s"]
        rows += [
            (f"{label}FMU build, total (s)", f"{b['total']:.1f}", "< 60", b["total"] < 60),
            (f"{label}  of which model / codegen / compile (s)",
             f"{b['model']:.1f} / {b['codegen']:.2f} / {b['compile']:.1f}", "", None),
            (f"{label}FMU doStep 1 ms via fmpy, median (us)",
             f"{f['fmu_doStep_us_median']:.1f}", "<= 30", f["fmu_doStep_us_median"] <= 30),
            (f"{label}FMU doStep via fmpy, p90 / mean (us)",
             f"{f['fmu_doStep_us_p90']:.1f} / {f['fmu_doStep_us_mean']:.1f}", "", None),
            (f"{label}FMU doStep via plain ctypes, median (us)",
             f"{f['fmu_doStep_ctypes_us_median']:.1f}", "", None),
            (f"{label}set 2 inputs + doStep + get 6 outputs via fmpy, median (us)",
             f"{f['fmu_exchange_us_median']:.1f}", "", None),
            (f"{label}Python HybridSimulator per 1 ms period, mean (us)",
             f"{f['python_us_per_period']:.1f}", "", None),
            (f"{label}speed-up Python / FMU doStep (median; mean)",
             f"{f['ratio_median']:.1f}x; {f['ratio_mean']:.1f}x", ">= 10x",
             f["ratio_median"] >= 10)]
    print("\n| measure | value | target | met |\n|---|---:|---:|:---:|")
    for name, val, target, ok in rows:
        print(f"| {name} | {val} | {target} | {'' if ok is None else ('yes' if ok else 'NO')} |")
    if a.json:
        Path(a.json).write_text(json.dumps(fig, indent=1) + "\n")


if __name__ == "__main__":
    main()
