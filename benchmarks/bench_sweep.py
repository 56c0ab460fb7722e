"""Sweep throughput (runs per minute) on Dask with 1 and 2 local workers, against the same
runs done serially in this process (no Dask) measured in the same session.

    PYTHONPATH=. python benchmarks/bench_sweep.py [--spec examples/sweep/quick.toml]
        [--draws 20] [--steps 3] [--repeats 3]

Throughput is counted from the first submitted run to the last result (cluster start and
worker setup reported separately); the order of the configurations alternates between
repeats so machine load drifts hit them alike.
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
import time
from pathlib import Path

from orchestrator.sweep_draws import make_draw, run_keys
from orchestrator.sweep_engine import run_sweep
from orchestrator.sweep_runs import Artifacts, Resources, run_draw
from orchestrator.sweep_spec import load_spec

ROOT = Path(__file__).resolve().parents[1]


def serial(spec) -> tuple[float, float]:
    """(runs per minute, setup s) of the same runs in this process, one after another."""
    t0 = time.perf_counter()
    res = Resources(Artifacts.from_spec(spec))
    setup = time.perf_counter() - t0
    try:
        t0 = time.perf_counter()
        n = 0
        for k in run_keys(spec):
            run_draw(res, spec, k, make_draw(spec, k.family, k.draw))
            n += 1
        return 60 * n / (time.perf_counter() - t0), setup
    finally:
        res.close()


def dask(spec, workers: int) -> tuple[float, float]:
    with tempfile.TemporaryDirectory() as td:
        o = run_sweep(spec, Path(td) / "out", workers=workers)
    assert o.status == "completed" and o.workers == workers
    return o.runs_per_min, o.setup_s


def summary(name: str, v: list[float]) -> str:
    return f"{name}: median {statistics.median(v):.1f} (min {min(v):.1f}, max {max(v):.1f})"


def main() -> None:
    p = argparse.ArgumentParser()
    p.add_argument("--spec", type=Path, default=ROOT / "examples" / "sweep" / "quick.toml")
    p.add_argument("--draws", type=int, default=20)
    p.add_argument("--steps", type=int, default=3)
    p.add_argument("--repeats", type=int, default=3)
    a = p.parse_args()
    spec = load_spec(a.spec, {"draws": a.draws, "steps": a.steps})
    print(f"{spec.n_runs} runs per sweep ({len(spec.controllers)} controllers x "
          f"{len(spec.families)} families x {spec.draws} draws, {spec.steps} steps)")
    rates: dict[str, list[float]] = {"serial": [], "dask 1 worker": [], "dask 2 workers": []}
    setups: dict[str, list[float]] = {k: [] for k in rates}
    configs = [("serial", lambda: serial(spec)), ("dask 1 worker", lambda: dask(spec, 1)),
               ("dask 2 workers", lambda: dask(spec, 2))]
    for r in range(a.repeats):
        for name, fn in (configs if r % 2 == 0 else configs[::-1]):
            rate, setup = fn()
            rates[name].append(rate)
            setups[name].append(setup)
            print(f"  repeat {r + 1} {name}: {rate:.1f} runs/min (setup {setup:.1f} s)",
                  flush=True)
    print("runs per minute")
    for name, v in rates.items():
        print("  " + summary(name, v) + f"; setup median {statistics.median(setups[name]):.1f} s")
    one, two, ser = (statistics.median(rates[k]) for k in ("dask 1 worker", "dask 2 workers",
                                                           "serial"))
    print(f"scaling 2 workers / 1 worker: {two / one:.2f} (ideal 2.00 on 2 free cores)")
    print(f"dask 1 worker / serial in process: {one / ser:.2f} (Dask overhead per run)")


if __name__ == "__main__":
    main()
