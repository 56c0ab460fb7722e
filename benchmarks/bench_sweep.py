"""Sweep throughput (runs per minute) on Dask with 1 and 2 local workers, against the same
runs done serially in this process (no Dask) measured in the same session.

    PYTHONPATH=. python benchmarks/bench_sweep.py [--spec examples/sweep/quick.toml]
        [--draws 20] [--steps 3] [--repeats 3]

Throughput is counted from the first submitted run to the last result (cluster start and
worker setup excluded).  The two local clusters are started once and kept; the order of the
configurations alternates between repeats and the 2-worker / 1-worker ratio is taken per
repeat (back to back), so drifts of the machine's load hit both alike.  The load average
is printed with every measurement.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import tempfile
import time
from pathlib import Path

from orchestrator.sweep.draws import make_draw, run_keys
from orchestrator.sweep.engine import dask_client, run_sweep
from orchestrator.sweep.runs import Artifacts, Resources, run_draw
from orchestrator.sweep.spec import load_spec
from orchestrator.sweep.store import read_results

ROOT = Path(__file__).resolve().parents[1]


def serial(spec) -> tuple[float, float, float]:
    """(runs per minute, setup s, 1) of the same runs in this process, one after another."""
    t0 = time.perf_counter()
    res = Resources(Artifacts.from_spec(spec))
    setup = time.perf_counter() - t0
    try:
        t0 = time.perf_counter()
        n = 0
        for k in run_keys(spec):
            run_draw(res, spec, k, make_draw(spec, k.family, k.draw))
            n += 1
        return 60 * n / (time.perf_counter() - t0), setup, 1.0
    finally:
        res.close()


def dask(spec, address: str, workers: int) -> tuple[float, float, float]:
    """(runs per minute, setup s, worker busy fraction = sum of run times / (wall x
    workers))."""
    with tempfile.TemporaryDirectory() as td:
        o = run_sweep(spec, Path(td) / "out", scheduler=address)
        busy = sum(read_results(Path(td) / "out")["wall_s"].to_pylist())
    assert o.status == "completed" and o.workers == workers and o.errors == 0
    return o.runs_per_min, o.setup_s, busy / (o.wall_s * workers)


def summary(name: str, v: list[float]) -> str:
    return f"{name}: median {statistics.median(v):.3g} (min {min(v):.3g}, max {max(v):.3g})"


def main() -> None:
    p = argparse.ArgumentParser()
    p.add_argument("--spec", type=Path, default=ROOT / "examples" / "sweep" / "quick.toml")
    p.add_argument("--draws", type=int, default=20)
    p.add_argument("--steps", type=int, default=3)
    p.add_argument("--repeats", type=int, default=3)
    p.add_argument("--serial-only", action="store_true",
                   help="only the serial runs in this process (no Dask clusters)")
    p.add_argument("--json", type=Path, help="also write the rates (runs/min) to this file")
    a = p.parse_args()
    spec = load_spec(a.spec, {"draws": a.draws, "steps": a.steps})
    print(f"{spec.n_runs} runs per sweep ({len(spec.controllers)} controllers x "
          f"{len(spec.families)} families x {spec.draws} draws, {spec.steps} steps)")
    rates: dict[str, list[float]] = {"serial": [], "dask 1 worker": [], "dask 2 workers": []}
    setups: dict[str, list[float]] = {k: [] for k in rates}
    if a.serial_only:
        for r in range(a.repeats):
            rate, setup, _ = serial(spec)
            rates["serial"].append(rate)
            print(f"  repeat {r + 1} serial: {rate:.1f} runs/min (setup {setup:.1f} s, load "
                  f"average {os.getloadavg()[0]:.1f})", flush=True)
        print("runs per minute\n  " + summary("serial", rates["serial"]))
        if a.json:
            a.json.write_text(json.dumps({"runs_per_min": rates}, indent=1))
        return
    with dask_client(None, 1) as c1, dask_client(None, 2) as c2:
        a1, a2 = c1.scheduler.address, c2.scheduler.address
        configs = [("serial", lambda: serial(spec)),
                   ("dask 1 worker", lambda: dask(spec, a1, 1)),
                   ("dask 2 workers", lambda: dask(spec, a2, 2))]
        for r in range(a.repeats):
            for name, fn in (configs if r % 2 == 0 else configs[::-1]):
                load = os.getloadavg()[0]
                rate, setup, busy = fn()
                rates[name].append(rate)
                setups[name].append(setup)
                print(f"  repeat {r + 1} {name}: {rate:.1f} runs/min (setup {setup:.1f} s, "
                      f"workers busy {100 * busy:.0f} %, load average {load:.1f})", flush=True)
    print("runs per minute")
    for name, v in rates.items():
        print("  " + summary(name, v) + f"; setup median {statistics.median(setups[name]):.1f} s")
    ratio = [b / a for a, b in zip(rates["dask 1 worker"], rates["dask 2 workers"],
                                   strict=True)]
    over = [b / a for a, b in zip(rates["serial"], rates["dask 1 worker"], strict=True)]
    print("  " + summary("2 workers / 1 worker, per repeat (ideal 2.00 on 2 free cores)", ratio))
    print("  " + summary("dask 1 worker / serial in process, per repeat", over))
    if a.json:
        a.json.write_text(json.dumps({"runs_per_min": rates}, indent=1))


if __name__ == "__main__":
    main()
