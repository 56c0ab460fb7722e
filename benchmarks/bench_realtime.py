"""Real-time co-simulation at 1 kHz (paced to the wall clock, MCAP recording): does every
run complete, and how often does a deadline slip? Per run: ticks, the controller's late and
missed replies, the plant's own overruns (ticks begun a period or more after their slot),
the wall-clock slots it skipped to catch up, its largest lag, and the reply latency; then
the median and range over ``--runs``. The machines are shared: the load average is printed
with each run.

    PYTHONPATH=. python benchmarks/bench_realtime.py --gait gait.json --tube tube.json \
        [--controller clfqp] [--steps 5] [--runs 5] [--fmu human.fmu] [--json out.json]
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import tempfile
from pathlib import Path
from typing import Any

from orchestrator.cosim.config import CosimConfig
from orchestrator.cosim.master import run_cosim

COLUMNS = ("completed", "ticks", "late", "missed", "overruns", "skipped_slots", "max_lag_ms",
           "latency_median_us", "latency_p99_us", "real_time_factor")


def one_run(args: argparse.Namespace, rec: Path) -> dict[str, Any]:
    cfg = CosimConfig(controller=args.controller, gait=Path(args.gait), tube=Path(args.tube),
                      steps=args.steps, mode="realtime", record=rec,
                      fmu=Path(args.fmu) if args.fmu else None)
    res = run_cosim(cfg)
    return {"completed": not (res.faulted or res.fell) and res.steps >= args.steps,
            "ticks": res.ticks, "late": res.late, "missed": res.missed,
            "overruns": res.overruns, "skipped_slots": res.skipped_slots,
            "max_lag_ms": res.max_lag_ms,
            "latency_median_us": res.latency_us.get("median", float("nan")),
            "latency_p99_us": res.latency_us.get("p99", float("nan")),
            "real_time_factor": res.real_time_factor,
            "fault": res.fault_reason, "load": os.getloadavg()[0]}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--gait", required=True)
    ap.add_argument("--tube", required=True)
    ap.add_argument("--controller", default="clfqp")
    ap.add_argument("--steps", type=int, default=5)
    ap.add_argument("--runs", type=int, default=5)
    ap.add_argument("--fmu")
    ap.add_argument("--json")
    args = ap.parse_args()
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for k in range(args.runs):
            row = one_run(args, Path(tmp) / f"rt{k}.mcap")
            rows.append(row)
            print(f"run {k}: " + ", ".join(f"{c} {row[c]:.4g}" if isinstance(row[c], float)
                                           else f"{c} {row[c]}" for c in COLUMNS)
                  + f" (load {row['load']:.2f}){'; ' + row['fault'] if row['fault'] else ''}",
                  flush=True)
    print(f"completed {sum(r['completed'] for r in rows)} of {len(rows)}")
    for c in COLUMNS[1:]:
        v = [float(r[c]) for r in rows]
        print(f"{c:>20}: median {statistics.median(v):.4g} [{min(v):.4g} .. {max(v):.4g}]")
    if args.json:
        Path(args.json).write_text(json.dumps(rows, indent=1) + "\n")


if __name__ == "__main__":
    main()
