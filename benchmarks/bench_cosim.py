"""Lockstep co-simulation at 1 kHz with MCAP recording: real-time factor, the per-tick
breakdown, and the orchestrator overhead beyond (zenoh round trip incl. controller tick +
FMU step), every figure measured inside the same run; median and spread over ``--runs``.

    PYTHONPATH=. python benchmarks/bench_cosim.py --gait gait.json --tube tube.json \
        [--controller clfqp] [--steps 20] [--runs 3] [--fmu human.fmu] \
        [--no-pin] [--no-low-latency] [--poll-us 300] [--json out.json]

Per run (plant side, means per tick): ``tick``; ``fmu`` (all FMU calls: outputs, inputs,
doStep); ``round_trip`` (the cycle's frames sent -> its TorqueCmd in hand: zenoh both ways,
the node's frame checks, controller tick and encoding, and the plant's MCAP serialization
done meanwhile, itself reported as ``record`` (it stops once a controller frame is here and
leaves the rest for the next waits); ``wait`` is the part spent polling or blocked after
it); ``overhead`` = tick - round trip - FMU (reading FMU outputs into frames, frame
checks, queuing records, loop bookkeeping). Controller node (same run, its own clock):
``controller tick`` and ``node cycle`` (first frame of a cycle received -> reply sent).
CPU per tick of each process (all threads, zenoh's included) and involuntary context
switches per tick (preemption: the machine's other load) put the wall figures in context;
the load average is printed with each run (the machines are shared: quote ratios).
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import tempfile
from pathlib import Path
from typing import Any

from hp_model.atomic_io import atomic_write_text
from orchestrator.cosim.config import CosimConfig
from orchestrator.cosim.master import run_cosim
from orchestrator.cosim.result import CosimResult


def figures(res: CosimResult, mcap_bytes: int) -> dict[str, float]:
    """The figures of one run (us per tick unless named otherwise)."""
    t = res.timing_us
    n = max(1, res.ticks)
    node = res.node.get("timing_us", {})
    nu = res.node.get("usage", {})
    core = t["round_trip"] + t["fmu"]
    return {
        "real_time_factor": res.real_time_factor,
        "tick": t["tick"], "round_trip": t["round_trip"], "fmu": t["fmu"],
        "overhead": t["overhead"], "record (in round trip)": t["record"],
        "wait (in round trip)": t["wait"],
        "overhead % of (round trip + FMU)": 100 * t["overhead"] / core,
        "overhead % of tick": 100 * t["overhead"] / t["tick"],
        "reply median (latency)": res.latency_us.get("median", float("nan")),
        "reply p99 (latency)": res.latency_us.get("p99", float("nan")),
        "controller tick (node)": node.get("controller_tick", {}).get("mean_us", float("nan")),
        "node cycle (node)": node.get("cycle", {}).get("mean_us", float("nan")),
        "plant CPU per tick": res.usage.get("cpu_s", float("nan")) / n * 1e6,
        "node CPU per tick": nu.get("cpu_s", float("nan")) / n * 1e6,
        "plant preemptions per tick": res.usage.get("involuntary_switches", 0) / n,
        "node preemptions per tick": nu.get("involuntary_switches", 0) / n,
        "reply in before serialization ended (share)": res.reply_early,
        "MCAP MB": mcap_bytes / 1e6,
    }


def check_inputs(p: argparse.ArgumentParser, a: argparse.Namespace) -> None:
    """A one-line usage error for a missing gait, tube or FMU file or a count below 1."""
    for name in ("gait", "tube", "fmu"):
        f = getattr(a, name)
        if f is not None and not Path(f).is_file():
            p.error(f"--{name} {f}: no such file")
    if a.steps < 1 or a.runs < 1:
        p.error("--steps and --runs must be >= 1")


def summarize(runs: list[dict[str, float]], unit: str) -> dict[str, Any]:
    """Each figure's median, min, max and per-run values over ``runs``; printed as a
    table."""
    summary: dict[str, Any] = {}
    width = max(map(len, runs[0]))
    print(f"\n{f'figure ({unit} unless named)':<{width}}  median  [min .. max] over "
          f"{len(runs)} runs")
    for key in runs[0]:
        vals = [r[key] for r in runs]
        med = statistics.median(vals)
        summary[key] = {"median": med, "min": min(vals), "max": max(vals), "runs": vals}
        print(f"{key:<{width}}  {med:8.2f}  [{min(vals):.2f} .. {max(vals):.2f}]")
    return summary


def write_json(path: Path, args: argparse.Namespace, summary: dict[str, Any]) -> None:
    """The arguments and the figures, written atomically."""
    atomic_write_text(path, json.dumps({"config": {k: str(v) for k, v in vars(args).items()},
                                        "figures": summary}, indent=2))


def one_run(a: argparse.Namespace) -> tuple[dict[str, float], CosimResult]:
    with tempfile.TemporaryDirectory() as td:
        path = Path(td) / "b.mcap"
        res = run_cosim(CosimConfig(controller=a.controller, gait=a.gait, tube=a.tube,
                                    fmu=a.fmu, steps=a.steps, record=path,
                                    pin_cpus=not a.no_pin, low_latency=not a.no_low_latency,
                                    poll_us=a.poll_us))
        size = path.stat().st_size
    if res.faulted or res.missed:
        raise SystemExit(f"bench_cosim: run faulted or missed replies: {res.fault_reason}")
    return figures(res, size), res


def main() -> None:
    p = argparse.ArgumentParser()
    p.add_argument("--gait", required=True, type=Path)
    p.add_argument("--tube", required=True, type=Path)
    p.add_argument("--fmu", type=Path)
    p.add_argument("--controller", default="clfqp")
    p.add_argument("--steps", type=int, default=20)
    p.add_argument("--runs", type=int, default=3)
    p.add_argument("--no-pin", action="store_true", help="let the OS place both processes")
    p.add_argument("--no-low-latency", action="store_true",
                   help="zenoh's normal transport instead of the low-latency one")
    p.add_argument("--poll-us", type=float, default=CosimConfig.poll_us,
                   help="receive polling before blocking, both sides (0: block at once)")
    p.add_argument("--json", type=Path)
    a = p.parse_args()
    check_inputs(p, a)
    runs: list[dict[str, float]] = []
    for i in range(a.runs):
        load0 = os.getloadavg()[0]
        fig, res = one_run(a)
        runs.append(fig)
        print(f"run {i + 1}: {res.ticks} ticks, sim {res.sim_time:.3f} s, wall "
              f"{res.wall_time:.3f} s, RTF {fig['real_time_factor']:.2f}, tick "
              f"{fig['tick']:.0f} us, overhead {fig['overhead % of (round trip + FMU)']:.1f} %,"
              f" load average {load0:.1f} -> {os.getloadavg()[0]:.1f}", flush=True)
    summary = summarize(runs, "us per tick")
    rtf = summary["real_time_factor"]["median"]
    ovh = summary["overhead % of (round trip + FMU)"]["median"]
    print(f"\ntargets: real-time factor >= 5 (issue 22): {'met' if rtf >= 5 else 'NOT met'} "
          f"(median {rtf:.2f}); overhead <= 30 % of (round trip + FMU): "
          f"{'met' if ovh <= 30 else 'NOT met'} (median {ovh:.1f} %)")
    if a.json:
        write_json(a.json, a, summary)


if __name__ == "__main__":
    main()
